//! The build lock: one process (or thread) builds an environment, the others wait for it.
//!
//! `flock` on a lock file beside the venv: the kernel drops it when its holder dies, so a
//! killed build never leaves a lock behind. Separate opens conflict even within one process,
//! so two sessions of one client also build once. Lock files are never deleted (deleting one
//! that another process is about to lock would let two builds run).

use crate::error::{PyEnvError, io};
use std::fs::File;
use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::Path;
use std::time::{Duration, Instant};

/// A held lock; released when dropped.
pub(crate) struct BuildLock {
    file: File,
}

impl Drop for BuildLock {
    fn drop(&mut self) {
        // SAFETY: the descriptor is open for the lifetime of `self.file`.
        unsafe { libc::flock(self.file.as_raw_fd(), libc::LOCK_UN) };
    }
}

fn try_lock(file: &File) -> bool {
    // SAFETY: as above; LOCK_NB makes it return at once.
    unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// Takes the lock at `path`, waiting up to `wait`; `on_wait` is called once with the
/// holder's description when it has to wait.
pub(crate) fn acquire(
    name: &str,
    path: &Path,
    wait: Duration,
    on_wait: impl FnOnce(&str),
) -> Result<BuildLock, PyEnvError> {
    let mut file = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(io(name, "open the lock file", path))?;
    let start = Instant::now();
    let mut on_wait = Some(on_wait);
    while !try_lock(&file) {
        let holder = holder(&mut file);
        if let Some(f) = on_wait.take() {
            f(&holder);
        }
        if start.elapsed() >= wait {
            return Err(PyEnvError::LockTimeout {
                name: name.to_string(),
                holder,
                waited_s: start.elapsed().as_secs(),
            });
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    // Who holds it, for the messages of those who wait.
    let _ = file.set_len(0);
    let _ = file.rewind();
    let _ = write!(file, "pid {}", std::process::id());
    let _ = file.flush();
    Ok(BuildLock { file })
}

fn holder(file: &mut File) -> String {
    let mut text = String::new();
    let _ = file.rewind();
    let _ = file.read_to_string(&mut text);
    let text = text.trim();
    if text.is_empty() {
        "unknown pid".into()
    } else {
        text.to_string()
    }
}
