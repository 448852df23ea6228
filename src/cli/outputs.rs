//! Where a render writes (the EXR, the PNG beside it, the checkpoint and `--stats`), checked
//! before any work (docs/CLI.md, "Outputs"): a folder, a device or a FIFO at an output's
//! name, two outputs that are one file, or an output that is the scene, is refused with exit
//! status 2 and nothing written; a place where no file can be made is a failure (1), also
//! found before any work. Folders are made only once every refusal is past, and removed
//! again if a refusal still comes (`OutputPlan::undo_folders`).

use firstshot::Error;
use firstshot::files::not_a_file;
use std::fs::File;
use std::path::{Component, Path, PathBuf};

fn refuse(message: String) -> Error {
    Error::Usage(message)
}

fn os_failure(path: &Path, source: std::io::Error) -> Error {
    Error::Io { path: path.to_path_buf(), source }
}

/// The EXR path of `--out` (docs/CLI.md): an existing folder (or a path ending in `/`) takes
/// `<scene stem>.exr` inside it; a path without extension gets `.exr`; no `--out` writes
/// `<scene stem>.exr` in the current folder.
pub fn exr_path(out: Option<&Path>, scene: &Path) -> Result<PathBuf, Error> {
    let stem_exr = || PathBuf::from(scene.file_stem().unwrap_or(scene.as_os_str())).with_extension("exr");
    let Some(out) = out else { return Ok(stem_exr()) };
    if out.as_os_str().is_empty() {
        return Err(refuse("--out: the path is empty; give a file path such as out/image.exr, or a folder".into()));
    }
    let names_a_folder = out.as_os_str().as_encoded_bytes().ends_with(b"/") || out.is_dir();
    if names_a_folder {
        return Ok(out.join(stem_exr()));
    }
    match out.extension() {
        None => Ok(out.with_extension("exr")),
        Some(e) if e.eq_ignore_ascii_case("exr") => Ok(out.to_path_buf()),
        Some(e) => Err(refuse(format!(
            "--out {}: expected a .exr path (or no extension, or a folder), not .{}",
            out.display(),
            e.to_string_lossy()
        ))),
    }
}

/// The EXR of one of several images of a run, beside `exr` and named after it: `OUT.exr`
/// and the camera "door" (`--all-cameras`) give `OUT_door.exr`, frame 7 of a path
/// (`--path`) `OUT_0007.exr`. `what` names the part in a refusal ("camera", "frame").
pub fn exr_beside(exr: &Path, suffix: &str, what: &str) -> Result<PathBuf, Error> {
    let fits = !suffix.is_empty() && suffix.chars().all(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if !fits {
        return Err(refuse(format!(
            "{what} \"{suffix}\" cannot be part of a file name ({}_{suffix}.exr); give it a name of letters, digits, '-', '_' and '.'",
            exr.with_extension("").display()
        )));
    }
    let stem = exr.file_stem().unwrap_or_default().to_string_lossy();
    Ok(exr.with_file_name(format!("{stem}_{suffix}.exr")))
}

/// Where `--stats` goes: a file replaced through a temporary file and a rename, or, for
/// an existing device or pipe (`/dev/null`, a FIFO with a reader) or one of this process's
/// own descriptors (`/dev/stdout`), the stream itself, opened now and written in place.
pub enum StatsTarget {
    File(PathBuf),
    Stream { path: PathBuf, file: File },
}

/// One image of a render: the EXR and the PNG beside it.
#[derive(Debug, Clone)]
pub struct ImagePaths {
    pub exr: PathBuf,
    pub png: PathBuf,
}

/// Every output of a render, checked: the paths to write (a symbolic link to a file is
/// written through, so the link stays a link), and the folders that must be made.
pub struct OutputPlan {
    /// Every image of the run (one per camera with `--all-cameras`, one per frame with
    /// `--path`), in order; never empty.
    pub images: Vec<ImagePaths>,
    pub checkpoint: PathBuf,
    /// A shard's part file (`merge::Part`), beside the EXR.
    pub part: Option<PathBuf>,
    pub stats: Option<StatsTarget>,
    /// Folders of the outputs, to make (if missing) and to probe with a temporary file.
    folders: Vec<PathBuf>,
    /// Folders this run made, innermost last.
    made: Vec<PathBuf>,
}

/// What an output's name holds now.
enum Existing {
    /// Nothing: a new file; or a file (maybe through a symbolic link) to replace, at its
    /// real path.
    File(PathBuf),
    /// A device, a FIFO or a socket (maybe through a symbolic link): `not_a_file`'s words.
    Stream(&'static str),
}

/// What is at `path`, refusing a folder and a link to nothing; `what` names the output in
/// messages ("--stats /x/s.json").
fn existing(path: &Path, what: &str) -> Result<Existing, Error> {
    let link = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        // Missing, or under a file (the folder check says which): a new file.
        Err(e) if matches!(e.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory) => {
            return Ok(Existing::File(path.to_path_buf()));
        }
        Err(e) => return Err(os_failure(path, e)),
    };
    let is_link = link.file_type().is_symlink();
    let target = if is_link {
        match std::fs::metadata(path) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(refuse(format!("{what}: a symbolic link to nothing; remove it or point it at a file")));
            }
            Err(e) => return Err(os_failure(path, e)),
        }
    } else {
        link
    };
    match not_a_file(&target) {
        None if is_link => Ok(Existing::File(std::fs::canonicalize(path).map_err(|e| os_failure(path, e))?)),
        None => Ok(Existing::File(path.to_path_buf())),
        Some("a folder") => Err(refuse(format!("{what}: is a folder; give a file name, or remove the folder"))),
        Some(other) => Ok(Existing::Stream(other)),
    }
}

/// An image output (EXR, PNG, checkpoint) is written many times (each checkpoint) and read
/// back by `--resume`: it must be a file.
fn image_output(path: &Path, what: &str) -> Result<PathBuf, Error> {
    match existing(path, what)? {
        Existing::File(p) => Ok(p),
        Existing::Stream(kind) => Err(refuse(format!(
            "{what}: is {kind}; images and checkpoints are written only to files (--stats may name a device or pipe)"
        ))),
    }
}

/// Opens an existing device or pipe for `--stats` now, without blocking: a FIFO that no
/// one reads is refused instead of hanging the run at its end.
fn open_stream(path: &Path) -> Result<File, Error> {
    use std::os::fd::AsRawFd as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let file =
        std::fs::OpenOptions::new().write(true).custom_flags(libc::O_NONBLOCK).open(path).map_err(|e| {
            match e.raw_os_error() {
                Some(libc::ENXIO) => {
                    os_failure(path, std::io::Error::other("a FIFO that no one reads (start the reader first)"))
                }
                _ => os_failure(path, e),
            }
        })?;
    // Blocking again for the write itself: a pipe's reader may be slower than we are.
    // SAFETY: fcntl on a descriptor this function owns, with flags read from it.
    unsafe {
        let flags = libc::fcntl(file.as_raw_fd(), libc::F_GETFL);
        if flags >= 0 {
            libc::fcntl(file.as_raw_fd(), libc::F_SETFL, flags & !libc::O_NONBLOCK);
        }
    }
    Ok(file)
}

/// The descriptor `path` names if it is one of this process's own (`/dev/stdout`,
/// `/dev/stderr`, `/dev/fd/N`, `/proc/self/fd/N`, directly or through links): written there
/// in place, as a shell's `> file` expects (the file is appended to at the shell's offset,
/// not replaced by a new one).
fn own_descriptor(path: &Path) -> Option<i32> {
    let named = |p: &Path| -> Option<i32> {
        let s = p.to_str()?;
        s.strip_prefix("/dev/fd/").or_else(|| s.strip_prefix("/proc/self/fd/"))?.parse().ok()
    };
    let mut at = path.to_path_buf();
    // A bound on the links followed, as the system's own (40).
    for _ in 0..40 {
        if let Some(fd) = named(&at) {
            return Some(fd);
        }
        let target = std::fs::read_link(&at).ok()?;
        at = match at.parent() {
            Some(dir) if target.is_relative() => dir.join(target),
            _ => target,
        };
    }
    None
}

/// A writable copy of this process's descriptor `fd`.
fn duplicate(path: &Path, fd: i32) -> Result<File, Error> {
    use std::os::fd::FromRawFd as _;
    // SAFETY: dup returns a new descriptor that only the File below owns.
    let copy = unsafe { libc::fcntl(fd, libc::F_DUPFD_CLOEXEC, 0) };
    if copy < 0 {
        return Err(os_failure(path, std::io::Error::last_os_error()));
    }
    Ok(unsafe { File::from_raw_fd(copy) })
}

/// One file, whichever path names it: the same (device, inode) for an existing file,
/// otherwise the real path of the longest part that exists (its symbolic links and `..`
/// resolved by the system) followed by the rest, with `.` and `..` taken as written.
#[derive(PartialEq, Eq, Debug)]
enum Identity {
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(path: &Path) -> Identity {
    use std::os::unix::fs::MetadataExt as _;
    if let Ok(m) = std::fs::metadata(path) {
        return Identity::Inode(m.dev(), m.ino());
    }
    let absolute = std::env::current_dir().map(|cwd| cwd.join(path)).unwrap_or_else(|_| path.to_path_buf());
    let parts: Vec<Component> = absolute.components().collect();
    for exists in (1..parts.len()).rev() {
        let Ok(mut real) = std::fs::canonicalize(parts[..exists].iter().collect::<PathBuf>()) else { continue };
        for part in &parts[exists..] {
            match part {
                Component::ParentDir => {
                    real.pop();
                }
                Component::CurDir => {}
                other => real.push(other),
            }
        }
        return Identity::Path(real);
    }
    Identity::Path(absolute)
}

/// `path`'s parts as written, each prefix in turn ("a", "a/b", ...), relative paths
/// starting from ".".
fn prefixes(path: &Path) -> Vec<PathBuf> {
    let mut out = vec![];
    let mut at = PathBuf::new();
    for part in path.components() {
        at.push(part);
        out.push(at.clone());
    }
    if path.is_relative() {
        out.insert(0, PathBuf::from("."));
    }
    out
}

/// The nearest folder that exists at or above `folder`: it must be a folder we may write
/// in (`access(2)`, which also sees a read-only file system). A failure here is found
/// without writing anything.
fn check_folder(folder: &Path) -> Result<(), Error> {
    for at in prefixes(folder).iter().rev() {
        match std::fs::metadata(at) {
            Ok(m) if m.is_dir() => {
                let c =
                    std::ffi::CString::new(at.as_os_str().as_encoded_bytes()).map_err(|e| os_failure(at, e.into()))?;
                // SAFETY: a NUL-terminated path that outlives the call.
                if unsafe { libc::access(c.as_ptr(), libc::W_OK | libc::X_OK) } != 0 {
                    return Err(os_failure(at, std::io::Error::last_os_error()));
                }
                return Ok(());
            }
            Ok(_) => {
                let e = std::io::Error::new(
                    std::io::ErrorKind::NotADirectory,
                    format!("{} is not a folder, so no folder can be made in it", at.display()),
                );
                return Err(os_failure(folder, e));
            }
            Err(e) if matches!(e.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory) => {}
            Err(e) => return Err(os_failure(at, e)),
        }
    }
    Ok(())
}

fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

impl OutputPlan {
    /// Checks every output of a render that writes `exr` (and the PNG and checkpoint beside
    /// it, and with `part` a shard's part file) and `stats`, from the scene at `scene`.
    /// Writes nothing and makes no folder.
    pub fn new(exr: &Path, stats: Option<&Path>, scene: &Path, part: bool) -> Result<OutputPlan, Error> {
        Self::with_images(exr, &[exr.to_path_buf()], stats, scene, part)
    }

    /// As `new`, for a run that writes the images `exrs` (each with its PNG beside it), and
    /// the checkpoint and part beside `exr` (which need not be one of them).
    pub fn with_images(
        exr: &Path,
        exrs: &[PathBuf],
        stats: Option<&Path>,
        scene: &Path,
        part: bool,
    ) -> Result<OutputPlan, Error> {
        let checkpoint = exr.with_extension("checkpoint");
        let part_path = exr.with_extension("part");
        let part = match part {
            true => Some(image_output(
                &part_path,
                &format!("--out {} (the shard's part beside the EXR)", part_path.display()),
            )?),
            false => None,
        };
        let out = |p: &Path| format!("--out {}", p.display());
        let pngs: Vec<PathBuf> = exrs.iter().map(|e| e.with_extension("png")).collect();
        let mut written = Vec::with_capacity(2 * exrs.len() + 1);
        for (exr, png) in exrs.iter().zip(&pngs) {
            written.push((image_output(exr, &out(exr))?, exr.as_path(), "the image"));
            written.push((image_output(png, &format!("{} (the PNG beside the EXR)", out(png)))?, png, "the PNG"));
        }
        written.push((
            image_output(&checkpoint, &format!("{} (the checkpoint beside the EXR)", out(&checkpoint)))?,
            checkpoint.as_path(),
            "the checkpoint",
        ));
        let stats_target = match stats {
            None => None,
            Some(path) if path.as_os_str().is_empty() => {
                return Err(refuse("--stats: the path is empty; give a file path such as stats.json".into()));
            }
            Some(path) => Some(match (own_descriptor(path), existing(path, &format!("--stats {}", path.display()))?) {
                (Some(fd), _) => StatsTarget::Stream { path: path.to_path_buf(), file: duplicate(path, fd)? },
                (None, Existing::File(p)) => StatsTarget::File(p),
                (None, Existing::Stream(_)) => {
                    StatsTarget::Stream { path: path.to_path_buf(), file: open_stream(path)? }
                }
            }),
        };

        // No two outputs may be one file, and none may be the scene.
        let mut named: Vec<(Identity, String)> = vec![(identity(scene), format!("the scene {}", scene.display()))];
        for (_, given, what) in &written {
            named.push((identity(given), format!("{what} {}", given.display())));
        }
        if part.is_some() {
            named.push((identity(&part_path), format!("the part {}", part_path.display())));
        }
        if let (Some(path), Some(target)) = (stats, &stats_target) {
            let id = match target {
                StatsTarget::File(p) => identity(p),
                StatsTarget::Stream { path, .. } => identity(path),
            };
            named.push((id, format!("--stats {}", path.display())));
        }
        for (i, (id, what)) in named.iter().enumerate().skip(1) {
            if let Some((_, other)) = named[..i].iter().find(|(other, _)| other == id) {
                return Err(refuse(format!("{what} is the same file as {other}; give another path")));
            }
        }

        let mut folders: Vec<PathBuf> = written.iter().map(|(p, _, _)| folder_of(p)).collect();
        folders.extend(part.iter().map(|p| folder_of(p)));
        if let Some(StatsTarget::File(p)) = &stats_target {
            folders.push(folder_of(p));
        }
        folders.sort();
        folders.dedup();
        for folder in &folders {
            check_folder(folder)?;
        }
        let checkpoint = written.pop().map(|w| w.0).unwrap_or_default();
        let images: Vec<ImagePaths> =
            written.chunks_exact(2).map(|w| ImagePaths { exr: w[0].0.clone(), png: w[1].0.clone() }).collect();
        Ok(OutputPlan { images, checkpoint, part, stats: stats_target, folders, made: Vec::new() })
    }

    /// Makes the missing folders and writes (and removes) a temporary file in each, so that
    /// an output that cannot be written is found before any work. On failure, the folders
    /// made are removed again.
    pub fn make_folders(&mut self) -> Result<(), Error> {
        let result = self.make_and_probe();
        if result.is_err() {
            self.undo_folders();
        }
        result
    }

    fn make_and_probe(&mut self) -> Result<(), Error> {
        for folder in self.folders.clone() {
            // As `mkdir -p`, each missing folder in turn, so that the ones made are known.
            for dir in prefixes(&folder) {
                let named = matches!(dir.components().next_back(), Some(Component::Normal(_)));
                if named && std::fs::symlink_metadata(&dir).is_err() {
                    std::fs::create_dir(&dir).map_err(|e| os_failure(&dir, e))?;
                    self.made.push(dir);
                }
            }
            let probe = firstshot::files::temporary_beside(&folder.join("probe"));
            std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&probe)
                .map_err(|e| os_failure(&folder, e))?;
            let _ = std::fs::remove_file(&probe);
        }
        Ok(())
    }

    /// Removes the folders this run made, if they are still empty (a refusal that comes
    /// after them leaves nothing behind).
    pub fn undo_folders(&mut self) {
        for dir in self.made.drain(..).rev() {
            let _ = std::fs::remove_dir(&dir);
        }
    }

    /// Writes the stats: a file through a temporary file and a rename, a stream in place.
    pub fn write_stats(&self, bytes: &[u8]) -> Result<(), Error> {
        use std::io::Write as _;
        match &self.stats {
            None => Ok(()),
            Some(StatsTarget::File(path)) => firstshot::files::write_atomically(path, bytes),
            Some(StatsTarget::Stream { path, file }) => {
                let mut file = file;
                file.write_all(bytes).and_then(|()| file.flush()).map_err(|e| os_failure(path, e))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_sees_through_dots_and_links() {
        let dir = std::env::temp_dir().join(format!("firstshot-identity-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("a")).unwrap();
        std::os::unix::fs::symlink(dir.join("a"), dir.join("link")).unwrap();
        assert_eq!(identity(&dir.join("a/x.exr")), identity(&dir.join("link/../a/./x.exr")));
        assert_eq!(identity(&dir.join("a/new/x.exr")), identity(&dir.join("link/new/x.exr")));
        assert_ne!(identity(&dir.join("a/x.exr")), identity(&dir.join("a/y.exr")));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
