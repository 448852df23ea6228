//! Files in and out, safe against what a careless or hostile user may name instead of a
//! file: inputs must be regular files (a FIFO would block the read forever, a device never
//! end), and outputs are written through a temporary file and a rename, so that a reader
//! sees the old or the new file, never half of one.

use crate::{Error, Result};
use std::io::Read as _;
use std::path::{Path, PathBuf};

/// What a path names, in words, when it is not a regular file: "a folder", "a FIFO (named
/// pipe)", ... `None` for a regular file.
pub fn not_a_file(metadata: &std::fs::Metadata) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt as _;
    let t = metadata.file_type();
    if t.is_file() {
        None
    } else if t.is_dir() {
        Some("a folder")
    } else if t.is_fifo() {
        Some("a FIFO (named pipe)")
    } else if t.is_char_device() || t.is_block_device() {
        Some("a device")
    } else if t.is_socket() {
        Some("a socket")
    } else {
        Some("not a regular file")
    }
}

/// Why an input could not be read.
#[derive(Debug)]
pub enum ReadError {
    /// The path names something other than a regular file ("a folder", "a FIFO", ...).
    NotAFile(&'static str),
    Io(std::io::Error),
}

impl std::fmt::Display for ReadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReadError::NotAFile(what) => write!(f, "{what}, not a file"),
            ReadError::Io(e) => write!(f, "{e}"),
        }
    }
}

/// Reads a regular file (following symbolic links). Anything else is refused before it is
/// read, and the file is opened without blocking, so that a FIFO swapped in between the
/// check and the open cannot hang the read either.
pub fn read_input(path: &Path) -> std::result::Result<Vec<u8>, ReadError> {
    use std::os::unix::fs::OpenOptionsExt as _;
    let metadata = std::fs::metadata(path).map_err(ReadError::Io)?;
    if let Some(what) = not_a_file(&metadata) {
        return Err(ReadError::NotAFile(what));
    }
    // O_NONBLOCK only matters for FIFOs and devices (opening a FIFO blocks until a writer
    // comes); reads of a regular file ignore it.
    let mut file =
        std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK).open(path).map_err(ReadError::Io)?;
    let metadata = file.metadata().map_err(ReadError::Io)?;
    if let Some(what) = not_a_file(&metadata) {
        return Err(ReadError::NotAFile(what));
    }
    let mut bytes = Vec::with_capacity(metadata.len() as usize);
    file.read_to_end(&mut bytes).map_err(ReadError::Io)?;
    Ok(bytes)
}

/// `read_input` for an input named on the command line or in a scene: a failure is the
/// user's to fix (`Error::Input`, exit status 2), and names the file once.
pub fn read_named_input(path: &Path) -> Result<Vec<u8>> {
    read_input(path).map_err(|e| Error::Input { path: path.to_path_buf(), message: e.to_string() })
}

/// A name for a temporary file beside `path`: short and ASCII whatever `path`'s own name is
/// (a name near the file system's length limit must not fail only because of the suffix),
/// and unique within the process.
pub fn temporary_beside(path: &Path) -> PathBuf {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = format!(".firstshot-{}-{n}.tmp", std::process::id());
    match path.parent() {
        Some(dir) => dir.join(name),
        None => PathBuf::from(name),
    }
}

fn io_error(path: &Path, source: std::io::Error) -> Error {
    Error::Io { path: path.to_path_buf(), source }
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename. The
/// rename replaces whatever is at `path`: callers that must not replace a symbolic link or a
/// device resolve or refuse those first (the CLI does, `docs/CLI.md`).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temporary_beside(path);
    std::fs::write(&tmp, bytes).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io_error(path, e)
    })?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io_error(path, e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_must_be_regular_files() {
        let dir = std::env::temp_dir().join(format!("firstshot-files-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a.txt");
        std::fs::write(&file, b"abc").unwrap();
        assert_eq!(read_input(&file).unwrap(), b"abc");
        assert!(matches!(read_input(&dir), Err(ReadError::NotAFile("a folder"))));
        assert!(matches!(read_input(Path::new("/dev/null")), Err(ReadError::NotAFile("a device"))));
        let fifo = dir.join("fifo");
        let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        assert!(matches!(read_input(&fifo), Err(ReadError::NotAFile("a FIFO (named pipe)"))));
        let missing = read_named_input(&dir.join("missing")).unwrap_err();
        assert!(missing.is_usage(), "{missing}");
        // The OS error once, after the path.
        assert_eq!(missing.to_string().matches("No such file").count(), 1, "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn atomic_writes_leave_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("firstshot-files-w-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let long = dir.join("x".repeat(255));
        write_atomically(&long, b"1").unwrap();
        write_atomically(&long, b"2").unwrap();
        assert_eq!(std::fs::read(&long).unwrap(), b"2");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
