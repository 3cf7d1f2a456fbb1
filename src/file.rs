//! Reading input files safely: regular files only, with a byte cap enforced while
//! reading (never from metadata, which says 0 for pipes and devices).
//!
//! A FIFO, device, socket or directory is refused before a byte is read. On Unix the file
//! is opened non-blocking (opening a FIFO with no writer would otherwise wait forever)
//! and its type is checked again on the open handle, so swapping the path for a FIFO
//! between the check and the open cannot make the read hang. Writing output files whole or
//! not at all is [`atomic`] (feature `files`, for the desktop crates).

#[cfg(feature = "files")]
pub mod atomic;

use std::io::Read;
use std::path::Path;

/// Why an input file could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FileError {
    /// The path names something other than a regular file.
    #[error("{path}: is {what}; only regular files are read")]
    NotRegular {
        /// The path as given.
        path: String,
        /// What it is instead (`a directory`, `a FIFO`, ...).
        what: &'static str,
    },
    /// The file holds more than the cap.
    #[error("{path}: larger than the limit of {limit} bytes for {role}")]
    TooLarge {
        /// The path as given.
        path: String,
        /// What the file was read as (`a parameter file`, ...).
        role: &'static str,
        /// The cap, bytes.
        limit: u64,
    },
    /// The operating system refused (missing, no permission, ...).
    #[error("{path}: {}", io_message(.source))]
    Io {
        /// The path as given.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
}

impl FileError {
    /// What went wrong, without the path (for errors that name the path themselves).
    pub fn reason(&self) -> String {
        match self {
            FileError::NotRegular { what, .. } => format!("is {what}; only regular files are read"),
            FileError::TooLarge { role, limit, .. } => format!("larger than the limit of {limit} bytes for {role}"),
            FileError::Io { source, .. } => io_message(source),
        }
    }
}

/// The OS error's text without Rust's ` (os error N)` suffix.
fn io_message(e: &std::io::Error) -> String {
    let s = e.to_string();
    match s.find(" (os error") {
        Some(i) => s[..i].to_string(),
        None => s,
    }
}

/// What a non-regular file type is, in words.
fn kind_of(t: std::fs::FileType) -> Option<&'static str> {
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO");
        }
        if t.is_block_device() || t.is_char_device() {
            return Some("a device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

/// `text` with control characters escaped (`\n`, `\u{1b}`): for echoing a path or a
/// value a file gave, which must not move the cursor, retitle the terminal or forge a line.
pub fn escape(text: &str) -> String {
    text.chars().flat_map(|c| if c.is_control() { c.escape_default().collect::<Vec<_>>() } else { vec![c] }).collect()
}

/// A path as one safe line ([`escape`] of its display form).
pub fn shown(path: &Path) -> String {
    escape(&path.display().to_string())
}

/// Reads the regular file at `path`, at most `limit` bytes; `role` names what it is
/// read as in the error.
pub fn read_capped(path: &Path, limit: u64, role: &'static str) -> Result<Vec<u8>, FileError> {
    let io = |source| FileError::Io { path: shown(path), source };
    let file = open_regular(path)?;
    let mut out = Vec::new();
    file.take(limit.saturating_add(1)).read_to_end(&mut out).map_err(io)?;
    if out.len() as u64 > limit {
        return Err(FileError::TooLarge { path: shown(path), role, limit });
    }
    Ok(out)
}

/// Opens `path` for reading if it is a regular file (a link to one counts): a FIFO, a
/// device or a folder is refused before it is opened and checked again once open (opened
/// non-blocking, so a FIFO swapped in meanwhile cannot hang the open).
pub fn open_regular(path: &Path) -> Result<std::fs::File, FileError> {
    let shown = || shown(path);
    let io = |source| FileError::Io { path: shown(), source };
    // Follows links: a link to a regular file is read as that file.
    let meta = std::fs::metadata(path).map_err(io)?;
    if let Some(what) = kind_of(meta.file_type()) {
        return Err(FileError::NotRegular { path: shown(), what });
    }
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.custom_flags(libc::O_NONBLOCK);
    }
    let file = opts.open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if let Some(what) = kind_of(meta.file_type()) {
        return Err(FileError::NotRegular { path: shown(), what });
    }
    Ok(file)
}

/// [`read_capped`] as UTF-8 text.
pub fn read_text_capped(path: &Path, limit: u64, role: &'static str) -> Result<String, FileError> {
    let bytes = read_capped(path, limit, role)?;
    String::from_utf8(bytes).map_err(|_| FileError::Io {
        path: path.display().to_string(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, "not UTF-8 text"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caps_while_reading_and_refuses_non_files() {
        let dir = std::env::temp_dir().join(format!("campro-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("ten");
        std::fs::write(&f, b"0123456789").unwrap();
        assert_eq!(read_capped(&f, 10, "a test").unwrap(), b"0123456789");
        let e = read_capped(&f, 9, "a test").unwrap_err().to_string();
        assert!(e.ends_with("larger than the limit of 9 bytes for a test"), "{e}");
        let e = read_capped(&dir, 9, "a test").unwrap_err().to_string();
        assert!(e.ends_with("is a directory; only regular files are read"), "{e}");
        #[cfg(unix)]
        {
            // A character device reports length 0 but never ends: refused before reading.
            let e = read_capped(Path::new("/dev/zero"), 9, "a test").unwrap_err().to_string();
            assert!(e.contains("is a device"), "{e}");
        }
        let e = read_capped(&dir.join("missing"), 9, "a test").unwrap_err().to_string();
        assert!(!e.contains("os error") && e.contains("missing"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
