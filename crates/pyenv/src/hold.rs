//! Environments in use: every worker of a session holds a shared `flock` on its venv's
//! manifest for as long as it runs (its start-up program takes it), so removing the venv
//! can tell that it is in use, and by whom, where deleting a folder would not care.
//!
//! A shared lock on a file opened read-only: it works in a read-only cache, and the kernel
//! drops it with the process. Removal takes it exclusively, which fails while any worker
//! holds it; the holders' pids come from `/proc/locks`.

use std::fs::File;
use std::os::fd::AsRawFd;
use std::os::unix::fs::MetadataExt;
use std::path::Path;

/// The exclusive hold on a venv, while it is removed; released when dropped.
pub(crate) struct Exclusive {
    _file: File,
}

/// The exclusive hold on `path`, or the pids of the processes that hold it shared (empty
/// when they cannot be told). `Ok(None)`: there is no such file (nothing to hold).
pub(crate) fn exclusive(path: &Path) -> std::io::Result<Option<Result<Exclusive, Vec<u32>>>> {
    let file = match File::open(path) {
        Ok(file) => file,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    // SAFETY: the descriptor is open for the lifetime of `file`; LOCK_NB returns at once.
    let locked = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 };
    if locked {
        return Ok(Some(Ok(Exclusive { _file: file })));
    }
    Ok(Some(Err(holders(&file.metadata()?))))
}

/// A shared hold on `path` for this process and whatever it `exec`s into: the descriptor
/// is left open across `exec` (no `CLOEXEC`), so the program that replaces this one holds
/// the environment for its whole life, as a worker does. Waits while a removal holds it
/// exclusively; an error when the file is gone (removed, or removed while waiting).
pub fn shared_across_exec(path: &Path) -> std::io::Result<std::os::fd::OwnedFd> {
    let fd = std::os::fd::OwnedFd::from(File::open(path)?);
    // SAFETY: `fd` is an open descriptor owned here for the duration of both calls.
    unsafe {
        if libc::flock(fd.as_raw_fd(), libc::LOCK_SH) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        let flags = libc::fcntl(fd.as_raw_fd(), libc::F_GETFD);
        if flags < 0 || libc::fcntl(fd.as_raw_fd(), libc::F_SETFD, flags & !libc::FD_CLOEXEC) < 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    if !path.exists() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            "removed while waiting for it",
        ));
    }
    Ok(fd)
}

/// The pids that hold a lock on the file of `meta`, from `/proc/locks`.
pub(crate) fn holders(meta: &std::fs::Metadata) -> Vec<u32> {
    let text = std::fs::read_to_string("/proc/locks").unwrap_or_default();
    let mut pids = holders_in(&text, meta.dev(), meta.ino());
    pids.sort_unstable();
    pids.dedup();
    pids.retain(|pid| *pid != std::process::id());
    pids
}

/// The pids of `/proc/locks` lines (`1: FLOCK  ADVISORY  READ  1234 fd:01:5678 0 EOF`) that
/// hold (not wait for: `->`) a lock on the file `dev`, `ino`.
fn holders_in(text: &str, dev: u64, ino: u64) -> Vec<u32> {
    // The kernel prints the device as `major:minor` in hex (glibc's encoding of `dev_t`).
    let major = ((dev >> 8) & 0xfff) | ((dev >> 32) & !0xfff);
    let minor = (dev & 0xff) | ((dev >> 12) & !0xff);
    text.lines()
        .filter(|line| !line.contains("->"))
        .filter_map(|line| {
            let fields: Vec<&str> = line.split_whitespace().collect();
            let (pid, file) = (fields.get(4)?, fields.get(5)?);
            let mut parts = file.split(':');
            let (maj, min, inode) = (parts.next()?, parts.next()?, parts.next()?);
            let same = u64::from_str_radix(maj, 16).ok()? == major
                && u64::from_str_radix(min, 16).ok()? == minor
                && inode.parse::<u64>().ok()? == ino;
            same.then(|| pid.parse().ok()).flatten()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A process that holds the file it is given as a worker does, says so, and waits.
    const HOLDER: &str = "import fcntl, os, sys, time\n\
        fd = os.open(sys.argv[1], os.O_RDONLY)\n\
        fcntl.flock(fd, fcntl.LOCK_SH)\n\
        print('held', flush=True)\n\
        time.sleep(60)\n";

    #[test]
    fn a_shared_hold_refuses_the_exclusive_one_and_names_its_holder() {
        let dir = std::env::temp_dir().join(format!("envhub-hold-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("envhub-env.json");
        std::fs::write(&path, "{}").unwrap();
        // A child process holds it shared, as a worker's start-up does.
        let mut child = std::process::Command::new("python3")
            .args(["-c", HOLDER])
            .arg(&path)
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(child.stdout.take().unwrap()),
            &mut line,
        )
        .unwrap();
        assert_eq!(line.trim(), "held");
        let Err(pids) = exclusive(&path).unwrap().unwrap() else {
            panic!("taken exclusively while a worker held it");
        };
        assert_eq!(pids, vec![child.id()]);
        child.kill().unwrap();
        child.wait().unwrap();
        assert!(exclusive(&path).unwrap().unwrap().is_ok());
        assert!(exclusive(&dir.join("absent")).unwrap().is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn proc_locks_lines_are_matched_by_device_and_inode() {
        let text = "1: FLOCK  ADVISORY  READ  4242 00:2d:77 0 EOF\n\
                    1: -> FLOCK  ADVISORY  WRITE 4343 00:2d:77 0 EOF\n\
                    2: FLOCK  ADVISORY  READ  4444 00:2d:78 0 EOF\n\
                    3: POSIX  ADVISORY  WRITE 4545 08:01:77 0 EOF\n";
        assert_eq!(holders_in(text, 0x2d, 77), vec![4242]);
    }
}
