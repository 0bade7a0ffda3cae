//! Who may reach the hub daemon: its socket lives in a folder only its user can enter, is
//! readable and writable by that user alone, and every connection's peer is asked who it is
//! (`SO_PEERCRED`): only the daemon's own user (or root) is served. Requests carry adapter
//! paths, pickles and `PYTHONPATH`, so another user on the machine must never get through.

use std::os::unix::fs::PermissionsExt;
use std::os::unix::io::AsRawFd;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};

fn uid() -> u32 {
    envhub_core::private_dir::uid()
}

/// The folder of the default socket: this user's private folder
/// ([`envhub_core::private_dir`]), whose every component is checked before it is used.
pub(crate) fn default_dir() -> Option<PathBuf> {
    envhub_core::private_dir::base().ok()
}

/// Whether `socket` lies in the default folder: then that folder must pass the check.
pub(crate) fn in_default_dir(socket: &Path) -> bool {
    socket
        .parent()
        .is_some_and(|p| Some(p) == default_dir().as_deref())
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
