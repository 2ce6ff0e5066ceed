//! One run per output directory: `sdem run` and `sdem resume` hold an advisory lock on
//! `DIR/.sdem.lock` (which holds their process id) for the whole run, so that a second run
//! started with the same `--out` refuses instead of writing the same files. The lock is the
//! operating system's (`flock` on Unix, `LockFileEx` on Windows): a run that is killed releases
//! it with its process, so the file it leaves behind never blocks a later run.
//!
//! Taking the lock also creates the directory and a file in it: an output directory that
//! cannot be written is reported before the run starts.

use std::fs::{File, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// The lock file's name in the output directory.
pub const LOCK_FILE: &str = ".sdem.lock";

/// Why an output directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error("cannot write in the output directory {dir} ({action})")]
    NotWritable {
        dir: String,
        action: &'static str,
        source: std::io::Error,
    },
    #[error(
        "output directory {dir} is in use by another sdem run ({holder}, lock file {file}); \
         wait for it to end or choose another --out"
    )]
    InUse {
        dir: String,
        file: String,
        holder: String,
    },
}

/// The held lock of an output directory; released when dropped (or when the process ends).
#[derive(Debug)]
pub struct OutputLock {
    _file: File,
    path: PathBuf,
}

impl OutputLock {
    /// Creates `dir` if needed and takes its lock; fails at once (without waiting) when another
    /// process holds it, naming that process.
    // `File::try_lock` is std's since Rust 1.89; the crate's `rust-version` (1.85) is older
    // than what it needs already (let chains, 1.88), and the toolchain is 1.95.
    #[allow(clippy::incompatible_msrv)]
    pub fn acquire(dir: &Path) -> Result<Self, LockError> {
        let not_writable = |action: &'static str| {
            move |source| LockError::NotWritable {
                dir: dir.display().to_string(),
                action,
                source,
            }
        };
        std::fs::create_dir_all(dir).map_err(not_writable("creating it"))?;
        let path = dir.join(LOCK_FILE);
        let mut file = File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(not_writable("creating its lock file"))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                let holder = match text.trim().parse::<u32>() {
                    Ok(pid) => format!("process {pid}"),
                    Err(_) => "a process that is starting".to_string(),
                };
                return Err(LockError::InUse {
                    dir: dir.display().to_string(),
                    file: path.display().to_string(),
                    holder,
                });
            }
            Err(TryLockError::Error(e)) => {
                return Err(not_writable("locking its lock file")(e));
            }
        }
        // Ours now: our process id, for the message of a run that finds it taken.
        file.set_len(0)
            .and_then(|()| file.seek(SeekFrom::Start(0)).map(|_| ()))
            .and_then(|()| writeln!(file, "{}", std::process::id()))
            .and_then(|()| file.flush())
            .map_err(not_writable("writing its lock file"))?;
        Ok(Self { _file: file, path })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_is_refused_until_the_first_is_dropped() {
        let dir = std::env::temp_dir().join(format!("sdem-lock-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        let first = OutputLock::acquire(&dir).unwrap();
        assert_eq!(
            std::fs::read_to_string(first.path()).unwrap().trim(),
            std::process::id().to_string()
        );
        // Another open file description of the same file: refused, naming the holder.
        let message = OutputLock::acquire(&dir).unwrap_err().to_string();
        assert!(
            message.contains(&format!("process {}", std::process::id()))
                && message.contains(&dir.display().to_string()),
            "{message}"
        );
        drop(first);
        let again = OutputLock::acquire(&dir).unwrap();
        drop(again);
        std::fs::remove_dir_all(&dir).ok();
    }
}
