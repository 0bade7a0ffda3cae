//! Is a process still there? Liveness checks that work for any process of the same user.

/// A handle that tells when a process has exited, without being its parent: a Linux pidfd.
#[derive(Debug)]
pub struct ProcessWatch {
    pid: u32,
    fd: i32,
}

impl ProcessWatch {
    /// Watches `pid`. Fails if it does not exist.
    pub fn new(pid: u32) -> std::io::Result<ProcessWatch> {
        // SAFETY: pidfd_open takes a pid and flags and returns a new fd or -1.
        let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) } as i32;
        if fd < 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(ProcessWatch { pid, fd })
    }

    /// The watched pid.
    pub fn pid(&self) -> u32 {
        self.pid
    }

    /// Whether the process has exited (a zombie counts as exited).
    pub fn exited(&self) -> bool {
        let mut p = libc::pollfd {
            fd: self.fd,
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd, zero timeout.
        unsafe { libc::poll(&mut p, 1, 0) > 0 }
    }
}

impl Drop for ProcessWatch {
    fn drop(&mut self) {
        // SAFETY: we own the fd.
        unsafe { libc::close(self.fd) };
    }
}

/// Asks the kernel to kill this process (SIGKILL) when its parent dies, even in the middle of
/// a step, so a crashed owner never leaves workers behind; fails if the parent is no longer
/// `parent` (it died before the request could take effect).
///
/// For a spawned child between fork and exec (`CommandExt::pre_exec`): the request survives
/// `exec`, and this makes two system calls and allocates nothing, as code there must. The
/// kernel sends the signal when the parent *thread* that forked the child ends, so the parent
/// must spawn from a thread that lives as long as it does.
pub fn die_with_parent(parent: u32) -> std::io::Result<()> {
    // SAFETY: prctl with PR_SET_PDEATHSIG and a signal number has no memory effects.
    if unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // The parent may have died before the request: then this process has been handed to
    // another one and will never get the signal.
    // SAFETY: getppid has no preconditions.
    if unsafe { libc::getppid() } as u32 != parent {
        return Err(std::io::Error::from_raw_os_error(libc::ESRCH));
    }
    Ok(())
}

/// A process held by a pidfd: signals sent through it reach that process or none, never one
/// that took its pid after it was reaped (by another parent: a daemon that started it).
#[derive(Debug)]
pub struct PidFd {
    fd: std::os::fd::OwnedFd,
    pid: u32,
}

impl PidFd {
    /// Holds process `pid` (fails if there is none).
    pub fn open(pid: u32) -> std::io::Result<PidFd> {
        use std::os::fd::FromRawFd;
        // SAFETY: pidfd_open takes a pid and flags and returns a new fd or -1.
        let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) };
        if fd < 0 {
            return Err(std::io::Error::last_os_error());
        }
        // SAFETY: a fresh fd that nothing else owns.
        let fd = unsafe { std::os::fd::OwnedFd::from_raw_fd(fd as i32) };
        Ok(PidFd { fd, pid })
    }

    /// The pid it was opened for.
    pub fn pid(&self) -> u32 {
        self.pid
    }

    /// The parent pid of the held process, read after the pidfd was opened: if it is still
    /// alive this is the process the fd holds (`None`: it has exited).
    pub fn parent(&self) -> Option<u32> {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid)).ok()?;
        let ppid = status
            .lines()
            .find_map(|l| l.strip_prefix("PPid:"))?
            .trim()
            .parse()
            .ok()?;
        // The pid may have been reaped and reused between the open and the read.
        self.is_alive().then_some(ppid)
    }

    /// Whether the held process has not exited.
    pub fn is_alive(&self) -> bool {
        use std::os::fd::AsRawFd;
        // SAFETY: signal 0 through a pidfd we own checks liveness and sends nothing.
        unsafe {
            libc::syscall(
                libc::SYS_pidfd_send_signal,
                self.fd.as_raw_fd(),
                0,
                std::ptr::null::<libc::siginfo_t>(),
                0,
            ) == 0
        }
    }

    /// Sends SIGKILL to the held process (nothing if it has exited).
    pub fn kill(&self) {
        use std::os::fd::AsRawFd;
        // SAFETY: a pidfd we own, a signal number, no siginfo.
        unsafe {
            libc::syscall(
                libc::SYS_pidfd_send_signal,
                self.fd.as_raw_fd(),
                libc::SIGKILL,
                std::ptr::null::<libc::siginfo_t>(),
                0,
            )
        };
    }
}

/// Sends SIGKILL to `pid` (a hung worker that is this process's unreaped child, so its pid
/// cannot have been reused).
pub fn kill(pid: u32) {
    // SAFETY: kill has no memory effects.
    unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
}

#[cfg(test)]
mod pidfd_tests {
    use super::PidFd;

    #[test]
    fn a_pidfd_holds_its_process_and_kills_only_it() {
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .spawn()
            .unwrap();
        let fd = PidFd::open(child.id()).unwrap();
        assert!(fd.is_alive());
        assert_eq!(fd.parent(), Some(std::process::id()));
        fd.kill();
        let status = child.wait().unwrap();
        assert!(!status.success(), "killed");
        assert!(!fd.is_alive(), "reaped: the pidfd holds nothing now");
        assert_eq!(fd.parent(), None);
        fd.kill(); // a no-op, whoever has the pid now
        assert!(PidFd::open(u32::MAX >> 2).is_err(), "no such process");
    }
}
