//! Helpers shared by the command-line tests.
#![allow(dead_code)]

use assert_cmd::Command;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The `campro` binary, with `RUST_BACKTRACE` set so that a backtrace leaking into a
/// message would show, and killed after [`COMMAND_LIMIT`] (a stalled run fails its test
/// instead of stopping the whole suite).
pub fn campro() -> Command {
    let mut c = Command::cargo_bin("campro").unwrap();
    c.env("RUST_BACKTRACE", "1").timeout(COMMAND_LIMIT);
    c
}

/// The longest one command of a test may run (the longest, `eval all` on a subset, takes
/// about two minutes).
pub const COMMAND_LIMIT: std::time::Duration = std::time::Duration::from_secs(600);

/// A bundled parameter file.
pub fn bundled(name: &str) -> PathBuf {
    campro_testkit::workspace_root().join("params").join(name)
}

/// Runs and expects failure with a one-line error that contains `needle`.
pub fn fails_with(cmd: &mut Command, needle: &str) {
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "succeeded; stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert!(err.contains(needle), "stderr {err:?} lacks {needle:?}");
    assert!(!err.contains("Caused by") && !err.contains("backtrace"), "{err}");
    assert!(
        err.lines().all(|l| {
            // Lines of a usage error as clap words it (a tip, the valid values, the usage).
            [
                "error",
                "warning",
                "simulated",
                "loading",
                "fetching",
                "  tip:",
                "  [possible values",
                "Usage:",
                "For more information",
            ]
            .iter()
            .any(|p| l.starts_with(p))
        }),
        "one line per error: {err}"
    );
}

/// Writes a PyTorch zip checkpoint: `pkl` as data.pkl and the named storages.
pub fn write_pt(path: &Path, pkl: &[u8], storages: &[(&str, Vec<u8>)]) {
    let f = std::fs::File::create(path).unwrap();
    let mut z = zip::ZipWriter::new(f);
    let o = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    z.start_file("archive/data.pkl", o).unwrap();
    z.write_all(pkl).unwrap();
    z.start_file("archive/byteorder", o).unwrap();
    z.write_all(b"little").unwrap();
    for (name, data) in storages {
        z.start_file(format!("archive/data/{name}"), o).unwrap();
        z.write_all(data).unwrap();
    }
    z.finish().unwrap();
}

/// Whether ffmpeg runs here; without it a video test skips with a message, except under
/// `CI=true` (where `.ci/run` installs it), where it fails.
pub fn ffmpeg_present() -> bool {
    let ok = std::process::Command::new("ffmpeg").arg("-version").output().is_ok_and(|o| o.status.success());
    if !ok {
        assert!(std::env::var("CI").as_deref() != Ok("true"), "CI=true but ffmpeg is missing (.ci/run installs it)");
        eprintln!("SKIP: ffmpeg not on PATH (apt-get install ffmpeg)");
    }
    ok
}

/// Runs `cmd` to its end and returns its output with the child's peak resident memory in
/// KiB (`ru_maxrss` of that child alone, through `wait4`; Linux). Panics after `limit`.
#[cfg(target_os = "linux")]
#[allow(clippy::zombie_processes, reason = "the child is reaped by wait4, which std's Child does not see")]
pub fn run_with_peak(cmd: &mut std::process::Command, limit: std::time::Duration) -> (std::process::Output, u64) {
    use std::io::Read;
    use std::os::unix::process::ExitStatusExt;
    let mut child = cmd
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let drain = |r: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            if let Some(mut r) = r {
                let _ = r.read_to_end(&mut v);
            }
            v
        })
    };
    let out = drain(child.stdout.take().map(|r| Box::new(r) as Box<dyn Read + Send>));
    let err = drain(child.stderr.take().map(|r| Box::new(r) as Box<dyn Read + Send>));
    let pid = child.id() as libc::pid_t;
    let began = std::time::Instant::now();
    let (status, usage) = loop {
        let mut status = 0;
        // SAFETY: wait4 on our own child's pid with valid out-pointers; WNOHANG polls.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        let got = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if got == pid {
            break (status, usage);
        }
        if began.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{cmd:?} ran over {} s", limit.as_secs());
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    };
    let output = std::process::Output {
        status: std::process::ExitStatus::from_raw(status),
        stdout: out.join().unwrap(),
        stderr: err.join().unwrap(),
    };
    (output, usage.ru_maxrss as u64)
}

/// Debian's headless Chromium, if installed; without it a browser test skips with a message,
/// except under `CI=true` (where `.ci/run` installs it), where it fails.
pub fn browser() -> Option<&'static str> {
    const BROWSER: &str = "chromium-headless-shell";
    let ok = std::process::Command::new(BROWSER).arg("--version").output().is_ok_and(|o| o.status.success());
    if !ok {
        assert!(std::env::var("CI").as_deref() != Ok("true"), "CI=true but {BROWSER} is missing (.ci/run installs it)");
        eprintln!("SKIP: {BROWSER} not on PATH (apt-get install {BROWSER})");
        return None;
    }
    Some(BROWSER)
}

/// Opens `page` (an HTML file) in the headless browser inside a frame and returns what the
/// loaded page holds: its images (with how many did not load, and their `src`), its
/// `<script>` and `<b>` elements, and its title.
pub fn open_in_browser(browser: &str, page: &Path) -> String {
    let dir = page.parent().unwrap();
    let harness = dir.join(".harness.html");
    let name = page.file_name().unwrap().to_string_lossy();
    std::fs::write(
        &harness,
        format!(
            r#"<!doctype html><html><body><script>
const f = document.createElement('iframe');
f.src = encodeURIComponent({name:?});
f.onload = () => {{
  const d = f.contentDocument;
  const imgs = [...d.images];
  const broken = imgs.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.getAttribute('src'));
  const out = document.createElement('pre');
  out.textContent = 'RES' + 'ULT images=' + imgs.length + ' broken=' + broken.length + ' scripts=' + d.scripts.length + ' bold=' + d.querySelectorAll('b').length + ' title=' + d.title + ' ' + broken.join(' ');
  document.body.appendChild(out);
}};
document.body.appendChild(f);
</script></body></html>"#
        ),
    )
    .unwrap();
    let out = std::process::Command::new(browser)
        .args([
            "--no-sandbox",
            "--disable-gpu",
            "--allow-file-access-from-files",
            "--virtual-time-budget=20000",
            "--dump-dom",
        ])
        .arg(format!("file://{}", harness.display()))
        .output()
        .unwrap();
    std::fs::remove_file(&harness).unwrap();
    let dom = String::from_utf8_lossy(&out.stdout).into_owned();
    let line =
        dom.lines().find(|l| l.contains("RESULT images=")).unwrap_or_else(|| panic!("the page did not load: {dom}"));
    line[line.find("RESULT").unwrap()..].to_string()
}
