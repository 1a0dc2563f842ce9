//! Files written in full or not at all.

use std::ffi::OsString;
use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use crate::error::{Error, Result};

/// The temporary files of every [`AtomicFile`] of the process not yet renamed or removed: what
/// [`remove_temporaries_then`] removes when a command must stop at once (a second Ctrl-C).
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn pending() -> MutexGuard<'static, Vec<PathBuf>> {
    // A panic while the lock was held leaves a list that is still right.
    PENDING.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes the temporary file of every [`AtomicFile`] in flight, then runs `then` (which cannot
/// return: typically `|| std::process::exit(status)`) while still holding the list's lock, so that no
/// temporary file is created, renamed into place or left between the removal and the end of the
/// process. For a command line that must stop at once (a second interrupt) without leaving a
/// partial or temporary file; a normal end never needs it (each file removes its own).
pub fn remove_temporaries_then(then: impl FnOnce() -> std::convert::Infallible) -> ! {
    let list = pending();
    for temp in list.iter() {
        let _ = std::fs::remove_file(temp);
    }
    match then() {}
}

/// A file written in full or not at all: bytes go to a hidden temporary file beside the target
/// (same folder, so the final rename stays on one file system and is atomic), renamed into place
/// by [`AtomicFile::commit`] or [`AtomicFile::persist`]. Dropped before that (an error, a panic),
/// it removes the temporary file.
///
/// Every file softvk writes (images, meshes, CSV, JSON, GIF) goes through it, from the library
/// and the command line alike. [`AtomicFile::commit`] writes a byte buffer;
/// [`AtomicFile::take_file`] + [`AtomicFile::persist`] serve writers that stream into their sink.
///
/// Hand-rolled rather than the `tempfile` crate: `tempfile` creates its files with mode 0600,
/// which the rename would carry over to the user's output, while `create_new` here gives the
/// usual permissions (0666 & umask) of any file the user creates.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    temp: PathBuf,
    file: Option<File>,
}

impl AtomicFile {
    /// Creates the temporary file now, so an unwritable destination fails before any work.
    pub fn create(target: &Path) -> Result<AtomicFile> {
        let name = target
            .file_name()
            .ok_or_else(|| Error::Input(format!("{}: not a file name", target.display())))?;
        if target.is_dir() {
            return Err(Error::Input(format!(
                "{}: is a folder, not a file",
                target.display()
            )));
        }
        let dir = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        // Unique among processes (pid) and among calls in one process (counter).
        static COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut temp_name = OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".softvk-{}-{n}.tmp", std::process::id()));
        let temp = dir.join(temp_name);
        let mut list = pending();
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)
            .map_err(|source| Error::Io {
                path: target.to_path_buf(),
                source,
            })?;
        list.push(temp.clone());
        drop(list);
        Ok(AtomicFile {
            target: target.to_path_buf(),
            temp,
            file: Some(file),
        })
    }

    /// The file to be written.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Writes `bytes` and renames the file into place.
    pub fn commit(mut self, bytes: &[u8]) -> Result<()> {
        let mut file = self.take_file();
        file.write_all(bytes).map_err(|e| self.io(e))?;
        self.persist(file)
    }

    /// The temporary file, for a writer that streams into it; give it back to
    /// [`AtomicFile::persist`]. Until then, dropping `self` still removes the temporary file.
    ///
    /// # Panics
    /// When called twice.
    pub fn take_file(&mut self) -> File {
        self.file
            .take()
            .expect("AtomicFile::take_file called twice")
    }

    /// Flushes `file` (the one [`AtomicFile::take_file`] gave) to disk and renames it into place.
    pub fn persist(mut self, file: File) -> Result<()> {
        file.sync_all().map_err(|e| self.io(e))?;
        drop(file);
        let mut list = pending();
        std::fs::rename(&self.temp, &self.target).map_err(|e| self.io(e))?;
        // Renamed: nothing left for Drop (or an interrupt) to remove.
        list.retain(|t| *t != self.temp);
        self.temp = PathBuf::new();
        Ok(())
    }

    /// An I/O error while writing the target.
    pub fn io(&self, source: std::io::Error) -> Error {
        Error::Io {
            path: self.target.clone(),
            source,
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        drop(self.file.take());
        if !self.temp.as_os_str().is_empty() {
            let mut list = pending();
            let _ = std::fs::remove_file(&self.temp);
            list.retain(|t| *t != self.temp);
        }
    }
}
