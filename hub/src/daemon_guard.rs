//! Who may reach the hub daemon: its socket lives in a folder only its user can enter, is
//! readable and writable by that user alone, and every connection's peer is asked who it is
//! (`SO_PEERCRED`): only the daemon's own user (or root) is served. Requests carry adapter
//! paths, pickles and `PYTHONPATH`, so another user on the machine must never get through.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::io::AsRawFd;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};

fn uid() -> u32 {
    // SAFETY: getuid has no preconditions.
    unsafe { libc::getuid() }
}

/// The folder of the default socket when `XDG_RUNTIME_DIR` is unset: `<tmp>/envhub-<uid>`.
pub(crate) fn private_dir() -> PathBuf {
    std::env::temp_dir().join(format!("envhub-{}", uid()))
}

/// Creates `dir` (mode 0700) if missing and checks that it is this user's and closed to
/// everyone else: a folder another user made first, or opened up, is refused.
pub(crate) fn ensure_private_dir(dir: &Path) -> Result<(), String> {
    match std::fs::create_dir(dir) {
        Ok(()) => {
            std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
                .map_err(|e| format!("cannot make `{}` private: {e}", dir.display()))?;
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(format!("cannot create `{}`: {e}", dir.display())),
    }
    check_private_dir(dir)
}

/// Checks that `dir` is a folder (not a link) of this user that no one else may enter.
pub(crate) fn check_private_dir(dir: &Path) -> Result<(), String> {
    let meta = std::fs::symlink_metadata(dir)
        .map_err(|e| format!("cannot inspect `{}`: {e}", dir.display()))?;
    if !meta.is_dir() {
        return Err(format!("`{}` is not a folder", dir.display()));
    }
    if meta.uid() != uid() {
        return Err(format!(
            "`{}` belongs to uid {}, not to this user (uid {}); another user may have made it first\nhint: remove it, or set XDG_RUNTIME_DIR or `--socket` to a folder of your own",
            dir.display(),
            meta.uid(),
            uid()
        ));
    }
    if meta.mode() & 0o077 != 0 {
        return Err(format!(
            "`{}` has mode {:o}; other users could reach the socket in it\nhint: `chmod 700 {}`",
            dir.display(),
            meta.mode() & 0o777,
            dir.display()
        ));
    }
    Ok(())
}

/// Makes a freshly bound socket readable and writable by its user alone.
pub(crate) fn restrict_socket(socket: &Path) -> Result<(), String> {
    std::fs::set_permissions(socket, std::fs::Permissions::from_mode(0o600))
        .map_err(|e| format!("cannot restrict the socket's mode: {e}"))
}

/// The uid of the process at the other end of `stream`.
pub(crate) fn peer_uid(stream: &UnixStream) -> std::io::Result<u32> {
    peer_cred(stream).map(|(_, uid)| uid)
}

/// The pid and uid of the process at the other end of `stream`, as the kernel recorded them
/// when the connection was made.
pub(crate) fn peer_cred(stream: &UnixStream) -> std::io::Result<(u32, u32)> {
    let mut cred = libc::ucred {
        pid: 0,
        uid: 0,
        gid: 0,
    };
    let mut len = std::mem::size_of::<libc::ucred>() as libc::socklen_t;
    // SAFETY: a valid socket fd, an out-buffer of `len` bytes for SO_PEERCRED.
    let rc = unsafe {
        libc::getsockopt(
            stream.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_PEERCRED,
            (&mut cred as *mut libc::ucred).cast(),
            &mut len,
        )
    };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok((cred.pid as u32, cred.uid))
}

/// Whether a peer of uid `peer` may use this daemon: its own user, or root.
pub(crate) fn peer_allowed(peer: u32) -> bool {
    peer == uid() || peer == 0
}
