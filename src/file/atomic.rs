//! Output files written whole or not at all, the one way every desktop command writes them:
//! the bytes go to a temporary file in the destination's folder, are flushed to disk, and
//! the file is renamed over the destination, so a reader (or a crash) never sees half a file.
//! The file gets the permissions of any file the user creates (0666 less the umask on Unix),
//! not the temporary file's private 0600.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Temporary files made by [`temporary_beside`] and not yet renamed into place: what
/// [`remove_partial_files`] deletes when the process is interrupted.
static PARTIAL: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Deletes every temporary output file of this process that was not finished (for a
/// SIGINT/SIGTERM handler: destructors do not run when a signal ends the process).
/// Returns how many were deleted.
pub fn remove_partial_files() -> usize {
    remove_partial_files_where(|_| true)
}

/// [`remove_partial_files`] for the unfinished files `which` picks; the others stay listed
/// (tests pick their own folder, leaving other tests' writes alone).
fn remove_partial_files_where(which: impl Fn(&Path) -> bool) -> usize {
    let mut list = PARTIAL.lock().unwrap_or_else(|p| p.into_inner());
    let (gone, kept): (Vec<PathBuf>, Vec<PathBuf>) = std::mem::take(&mut *list).into_iter().partition(|p| which(p));
    *list = kept;
    drop(list);
    gone.iter().filter(|p| std::fs::remove_file(p).is_ok()).count()
}

/// Writes `bytes` to `path` atomically, creating missing parent folders. With `replace`
/// false an existing `path` is left alone and the call fails with
/// [`std::io::ErrorKind::AlreadyExists`] (checked at the rename, so no race can clobber it).
/// With `replace` true only a regular file is replaced: a symbolic link, folder, device,
/// FIFO or socket at `path` is refused ([`std::io::ErrorKind::InvalidInput`]), so the
/// rename can never swap a device node or a link's target for a file. A parent that is a
/// file, not a folder, is refused the same way.
pub fn write(path: &Path, bytes: &[u8], replace: bool) -> std::io::Result<()> {
    let mut tmp = temporary_beside(path, ".tmp")?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    persist(tmp, path, replace)
}

/// A file written beside its destination, removed when dropped unless persisted.
pub type Temporary = tempfile::NamedTempFile;

/// A temporary file (`.campro-*SUFFIX`, permissions of an ordinary new file) in the folder
/// `path` will be in, which is created if missing: for output that a program (ffmpeg)
/// writes by name before [`persist`] renames it over `path`. Refuses what [`write`] refuses.
pub fn temporary_beside(path: &Path, suffix: &str) -> std::io::Result<Temporary> {
    let refuse = |what: String| Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, what));
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Some(up) = dir.ancestors().find(|a| !a.as_os_str().is_empty() && std::fs::symlink_metadata(a).is_ok()) {
        if !up.is_dir() {
            return refuse(format!("{} is not a folder", up.display()));
        }
    }
    check_replaceable(path)?;
    std::fs::create_dir_all(dir)?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(".campro-").suffix(suffix);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // The mode given to open(2), which the umask then reduces, as for any new file.
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let tmp = builder.tempfile_in(dir)?;
    PARTIAL.lock().unwrap_or_else(|p| p.into_inner()).push(tmp.path().to_path_buf());
    Ok(tmp)
}

/// Refuses a `path` that exists and is not a regular file (a symbolic link, folder,
/// device, FIFO or socket): only regular files are ever replaced.
fn check_replaceable(path: &Path) -> std::io::Result<()> {
    let Ok(m) = std::fs::symlink_metadata(path) else { return Ok(()) };
    let t = m.file_type();
    if t.is_file() {
        return Ok(());
    }
    let what = if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a folder"
    } else {
        "not a regular file"
    };
    Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("is {what}; only regular files are replaced")))
}

/// Renames the finished temporary file `tmp` over `path`: only over a regular file, and
/// only with `replace` (otherwise [`std::io::ErrorKind::AlreadyExists`], checked at the
/// rename).
pub fn persist(tmp: Temporary, path: &Path, replace: bool) -> std::io::Result<()> {
    if replace {
        check_replaceable(path)?;
    }
    PARTIAL.lock().unwrap_or_else(|p| p.into_inner()).retain(|p| p != tmp.path());
    let done = if replace { tmp.persist(path) } else { tmp.persist_noclobber(path) };
    done.map(|_| ()).map_err(|e| e.error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_whole_files_and_replaces_only_when_asked() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a/b/out.json");
        write(&p, b"first", false).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"first");
        let e = write(&p, b"second", false).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::AlreadyExists);
        assert_eq!(std::fs::read(&p).unwrap(), b"first");
        write(&p, b"second", true).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        // no temporary file left beside it
        let names: Vec<_> = std::fs::read_dir(p.parent().unwrap()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("out.json")]);
    }

    #[cfg(unix)]
    #[test]
    fn the_file_gets_the_permissions_of_an_ordinary_new_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let ordinary = dir.path().join("ordinary");
        std::fs::write(&ordinary, b"x").unwrap(); // 0666 less the umask
        let ours = dir.path().join("ours");
        write(&ours, b"x", false).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&ours), mode(&ordinary));
    }

    #[test]
    fn unfinished_temporary_files_are_removed_on_request() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("v.mkv");
        let tmp = temporary_beside(&out, ".mkv").unwrap();
        let path = tmp.path().to_path_buf();
        // What a signal does: the process ends without running destructors.
        std::mem::forget(tmp);
        assert!(path.exists());
        // (This test's folder only: the whole list would be other tests' writes in flight.)
        let ours = |p: &Path| p.starts_with(dir.path());
        assert_eq!(remove_partial_files_where(ours), 1);
        assert!(!path.exists());
        // A finished one is not touched.
        let done = temporary_beside(&out, ".mkv").unwrap();
        persist(done, &out, false).unwrap();
        assert_eq!(remove_partial_files_where(ours), 0);
        assert!(out.exists());
    }

    #[test]
    fn a_folder_in_the_way_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("taken")).unwrap();
        let e = write(&dir.path().join("taken"), b"x", true).unwrap_err();
        assert_eq!(e.to_string(), "is a folder; only regular files are replaced");
        // A parent that is a file: named, not "exists".
        std::fs::write(dir.path().join("file"), b"x").unwrap();
        let e = write(&dir.path().join("file/out.json"), b"x", false).unwrap_err();
        assert!(e.to_string().ends_with("file is not a folder"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn links_and_devices_are_never_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("target");
        std::fs::write(&target, b"keep").unwrap();
        let link = dir.path().join("link");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let e = write(&link, b"x", true).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
        // A FIFO (made by mkfifo(1), so no device node is ever at risk here).
        let fifo = dir.path().join("fifo");
        if std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success()) {
            let e = write(&fifo, b"x", true).unwrap_err();
            assert!(e.to_string().contains("not a regular file"), "{e}");
            assert!(!std::fs::symlink_metadata(&fifo).unwrap().file_type().is_file());
        }
    }
}
