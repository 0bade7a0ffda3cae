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

/// Sends SIGKILL to `pid` (a hung worker).
pub fn kill(pid: u32) {
    // SAFETY: kill has no memory effects.
    unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
}
