//! What the tool says and writes: lines on stdout that end quietly when the reader goes
//! away, errors as one escaped line, and outputs that are written whole, never over an
//! input, and never over an earlier run's without --force.

use anyhow::{bail, Context, Result};
pub(crate) use campro::file::{escape, shown};
use std::io::Write;
use std::path::{Path, PathBuf};

/// An error chain as one line: each cause's first line (a backtrace some libraries
/// append with `RUST_BACKTRACE` set never shows), a cause that the text so far already
/// says left out, the operating system's error numbers (" (os error 2)") dropped, control
/// characters escaped.
pub(crate) fn one_line(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = without_os_error_numbers(&cause.to_string());
        let first = text.lines().map(str::trim).find(|l| !l.is_empty()).unwrap_or_default();
        if first.is_empty() || out.contains(first) {
            continue;
        }
        // A cause that repeats the text so far (a path added twice) is not said again.
        let first = first.strip_prefix(out.as_str()).map(|r| r.trim_start_matches(": ")).unwrap_or(first);
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(first);
    }
    short(&escape(&out), MAX_ERROR_CHARS)
}

/// `text` without the " (os error N)" that `std::io::Error` appends to the system's own
/// words ("No such file or directory (os error 2)"): the number says nothing to a person.
fn without_os_error_numbers(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find(" (os error ") {
        let tail = &rest[i + " (os error ".len()..];
        let digits = tail.bytes().take_while(u8::is_ascii_digit).count();
        if digits > 0 && tail[digits..].starts_with(')') {
            out.push_str(&rest[..i]);
            rest = &tail[digits + 1..];
        } else {
            out.push_str(&rest[..i + 1]);
            rest = &rest[i + 1..];
        }
    }
    out.push_str(rest);
    out
}

/// An error about the input `path` as one line, the path said once (an error that names
/// it already is not prefixed with it again).
pub(crate) fn about(path: &Path, e: &anyhow::Error) -> String {
    let line = one_line(e);
    let p = shown(path);
    if line.contains(&p) {
        line
    } else {
        format!("{p}: {line}")
    }
}

/// Longest error line printed, characters.
pub(crate) const MAX_ERROR_CHARS: usize = 1000;

/// Writes one line to stdout; a closed stdout (`| head`) ends the command quietly.
pub(crate) fn say(args: std::fmt::Arguments) {
    if let Err(e) = writeln!(std::io::stdout().lock(), "{args}") {
        quiet_exit(e);
    }
}

/// Writes bytes to stdout, as [`say`].
pub(crate) fn say_bytes(bytes: &[u8]) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(bytes).and_then(|()| out.flush()) {
        quiet_exit(e);
    }
}

/// Ends the process after a failed write to stdout: quietly (status 0) when the reader
/// went away, with a one-line error otherwise.
fn quiet_exit(e: std::io::Error) -> ! {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(0);
    }
    eprintln!("error: standard output: {e}");
    std::process::exit(1);
}

/// `println!` through [`say`].
#[macro_export]
macro_rules! say {
    ($($t:tt)*) => { $crate::say(format_args!($($t)*)) };
}

/// A progress bar over `n` items on stderr, `label` before it (empty: none), with the
/// elapsed time and the time left.
pub(crate) fn count_bar(label: &str, n: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(n);
    let sep = if label.is_empty() { "" } else { " " };
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{label}{sep}{{bar:40}} {{pos}}/{{len}} {{elapsed_precise}} eta {{eta}}"
        ))
        .expect("valid template"),
    );
    bar
}

/// Writes `bytes` to `path` whole or not at all ([`campro::file::atomic::write`]). Refuses
/// to replace `path` unless `force` (checked once, at the rename).
pub(crate) fn write_atomic(path: &Path, bytes: &[u8], force: bool) -> Result<()> {
    output_result(path, campro::file::atomic::write(path, bytes, force))
}

/// An output write's result, with "exists (use --force ...)" for a refused overwrite.
pub(crate) fn output_result(path: &Path, r: std::io::Result<()>) -> Result<()> {
    match r {
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            bail!("{} exists (use --force to overwrite)", crate::shown(path))
        }
        r => r.with_context(|| path.display().to_string()),
    }
}

/// `text` cut to `max` characters, saying how much was left out (a value echoed from a
/// file or an argument must not flood the terminal).
pub(crate) fn short(text: &str, max: usize) -> String {
    let n = text.chars().count();
    if n <= max {
        return text.to_string();
    }
    let head: String = text.chars().take(max).collect();
    format!("{head}... ({} more characters)", n - max)
}

/// A path as it names a file, for comparing outputs that may not exist yet: the folder
/// resolved (links, `..`), the name kept.
pub(crate) fn file_key(p: &Path) -> PathBuf {
    if let Ok(c) = std::fs::canonicalize(p) {
        return c;
    }
    let parent = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match (std::fs::canonicalize(parent), p.file_name()) {
        (Ok(d), Some(n)) => d.join(n),
        _ => std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf()),
    }
}

/// Whether `a` and `b` name the same existing file (the same inode on Unix, through links).
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
        false
    }
    #[cfg(not(unix))]
    {
        matches!((std::fs::canonicalize(a), std::fs::canonicalize(b)), (Ok(x), Ok(y)) if x == y)
    }
}

/// Refuses an output that is one of the command's inputs: an output never replaces what
/// it was made from, `--force` or not.
pub(crate) fn not_an_input(flag: &str, output: &Path, inputs: &[&Path]) -> Result<()> {
    if let Some(i) = inputs.iter().find(|i| same_file(output, i)) {
        bail!(
            "{flag} {}: is an input of this command ({}); outputs never replace their inputs",
            crate::shown(output),
            crate::shown(i)
        );
    }
    Ok(())
}

/// Refuses an output folder that already holds files unless `force` (a quick look must
/// not replace the results of a long run), and a path that is not a folder.
/// `flag` names the option the folder came from.
pub(crate) fn check_output_folder(out: &Path, force: bool, flag: &str) -> Result<()> {
    match std::fs::read_dir(out) {
        Ok(mut entries) => {
            if entries.next().is_some() && !force {
                bail!(
                    "{flag} {}: the folder already holds files (an earlier run's?); choose another or pass --force",
                    out.display()
                );
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(_) if out.exists() => bail!("{flag} {}: is not a folder", crate::shown(out)),
        Err(e) => Err(e).with_context(|| format!("{flag} {}", crate::shown(out))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn os_error_numbers_are_dropped_and_nothing_else() {
        assert_eq!(
            without_os_error_numbers("a.png: No such file or directory (os error 2)"),
            "a.png: No such file or directory"
        );
        assert_eq!(without_os_error_numbers("x (os error 13): y (os error 2)"), "x: y");
        assert_eq!(without_os_error_numbers("kept (os error x) and (os error )"), "kept (os error x) and (os error )");
        let e = anyhow::Error::from(std::io::Error::from_raw_os_error(2)).context("photo.jpg");
        assert_eq!(one_line(&e), "photo.jpg: No such file or directory");
    }
}
