//! The files the tool writes: where they may go, checked before any work, and how they are written (atomically).
//!
//! # Policy
//! - **Output files** ([`check_output_file`]): the folder must exist (a missing folder is an error, as with most
//!   tools: a typo in a path should not create a tree of folders), must be a folder and writable, and the file
//!   must not be a folder. Commands check every output this way before they compute anything.
//! - **Output folders** ([`check_output_folder`]): options documented as folders the tool creates
//!   (`relight --frames DIR`, `demo --out`, `bench --out`) are created with any missing parents; what exists of
//!   the path must be folders, and the nearest existing one writable.
//! - **Atomic writes** ([`write_atomic`]): every file is written to a temporary file in the same folder, flushed
//!   to disk (`fsync`) and renamed over the target, so a run that fails or is killed half way leaves the previous
//!   file intact and no partial file (the temporary file is removed on failure; a killed run can leave one
//!   `.NAME.tmp-PID-N` file, never a truncated `NAME`). Nothing removes such a leftover (it may belong to a run
//!   still writing); a later write passes over its name if it meets it (a recycled process id) and is not
//!   otherwise affected by it.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Why an output path cannot be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FileError {
    /// The output file's folder does not exist.
    #[error("cannot write {}: folder {} does not exist (create it first)", path.display(), folder.display())]
    MissingFolder {
        /// The output file.
        path: PathBuf,
        /// Its folder.
        folder: PathBuf,
    },
    /// Part of the path that must be a folder is something else (e.g. a regular file).
    #[error("cannot write {}: {} is not a folder", path.display(), folder.display())]
    NotAFolder {
        /// The output file or folder.
        path: PathBuf,
        /// The part of its path that is not a folder.
        folder: PathBuf,
    },
    /// The output file is a folder.
    #[error("cannot write {}: it is a folder", path.display())]
    IsAFolder {
        /// The output file.
        path: PathBuf,
    },
    /// Creating, writing, flushing or renaming failed.
    #[error("writing {}: {source}", path.display())]
    Io {
        /// The file (or folder) concerned.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// The folder a file path lives in (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// A fresh temporary path beside `path`: `.NAME.tmp-PID-N` in the same folder.
fn temporary_beside(path: &Path) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    folder_of(path).join(format!(".{name}.tmp-{}-{n}", std::process::id()))
}

/// Creates a new temporary file beside `path` (see [`temporary_beside`]). A name that exists already is passed
/// over for the next one: a run killed half way leaves its temporary file behind, and a later process can get
/// the same process id (containers recycle small ids), so the same name.
fn create_temporary(path: &Path) -> std::io::Result<(PathBuf, File)> {
    loop {
        let temporary = temporary_beside(path);
        match OpenOptions::new().write(true).create_new(true).open(&temporary) {
            Ok(file) => return Ok((temporary, file)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(e),
        }
    }
}

/// Checks that `folder` is a writable folder by creating and removing a temporary file in it; `path` is the
/// output the check is for (named in the error).
fn check_writable(path: &Path, folder: &Path) -> Result<(), FileError> {
    let (probe, _) = create_temporary(&folder.join("probe"))
        .map_err(|source| FileError::Io { path: path.to_path_buf(), source })?;
    std::fs::remove_file(&probe).map_err(|source| FileError::Io { path: probe, source })
}

/// Checks that the file `path` can be written (see the module docs' policy): its folder exists, is a folder and
/// is writable, and `path` is not a folder. Writes nothing that stays.
///
/// # Errors
/// [`FileError`] saying which of these fails.
pub fn check_output_file(path: &Path) -> Result<(), FileError> {
    let folder = folder_of(path);
    // `metadata` follows symbolic links, as writing will.
    match std::fs::metadata(folder) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => {
            return Err(FileError::NotAFolder { path: path.to_path_buf(), folder: folder.to_path_buf() })
        }
        Err(_) => return Err(missing_or_not_a_folder(path, folder)),
    }
    if path.is_dir() {
        return Err(FileError::IsAFolder { path: path.to_path_buf() });
    }
    check_writable(path, folder)
}

/// For a folder that does not exist: [`FileError::NotAFolder`] naming the first ancestor that exists but is not a
/// folder, else [`FileError::MissingFolder`].
fn missing_or_not_a_folder(path: &Path, folder: &Path) -> FileError {
    for ancestor in folder.ancestors().skip(1).filter(|a| !a.as_os_str().is_empty()) {
        if let Ok(m) = std::fs::metadata(ancestor) {
            if !m.is_dir() {
                return FileError::NotAFolder { path: path.to_path_buf(), folder: ancestor.to_path_buf() };
            }
            break;
        }
    }
    FileError::MissingFolder { path: path.to_path_buf(), folder: folder.to_path_buf() }
}

/// Checks that the folder `dir` exists or can be created (see the module docs' policy): every part of it that
/// exists is a folder and the nearest existing one is writable. Creates nothing.
///
/// # Errors
/// [`FileError::NotAFolder`] or [`FileError::Io`].
pub fn check_output_folder(dir: &Path) -> Result<(), FileError> {
    for ancestor in dir.ancestors().filter(|a| !a.as_os_str().is_empty()) {
        if let Ok(m) = std::fs::metadata(ancestor) {
            if !m.is_dir() {
                return Err(FileError::NotAFolder {
                    path: dir.to_path_buf(),
                    folder: ancestor.to_path_buf(),
                });
            }
            return check_writable(dir, ancestor);
        }
    }
    check_writable(dir, Path::new("."))
}

/// Creates the output folder `dir` and its missing parents (for options documented as folders the tool creates).
///
/// # Errors
/// [`FileError::Io`] naming the folder.
pub fn create_output_folder(dir: &Path) -> Result<(), FileError> {
    std::fs::create_dir_all(dir).map_err(|source| FileError::Io { path: dir.to_path_buf(), source })
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, flushed to disk, renamed over `path`
/// (then the folder is flushed, so the rename survives a crash). On failure the temporary file is removed and
/// `path` is as it was.
///
/// # Errors
/// [`FileError::Io`] naming `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let io = |source| FileError::Io { path: path.to_path_buf(), source };
    let (temporary, mut file) = create_temporary(path).map_err(io)?;
    let written = (|| {
        file.write_all(bytes)?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&temporary, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&temporary);
        return Err(io(e));
    }
    // Flushing the folder makes the rename durable; some file systems do not support it, which loses nothing
    // but durability across a power cut, so its failure is not an error.
    if let Ok(folder) = File::open(folder_of(path)) {
        let _ = folder.sync_all();
    }
    Ok(())
}
