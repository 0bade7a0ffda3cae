//! This machine's hubs, for this user's clients: how a client finds a hub that listens on
//! loopback only, without multicast (loopback carries none, and scouting on a real interface
//! would reach the LAN).
//!
//! A hub that listens on loopback only writes its endpoint to a file in a folder only its user
//! can enter (`hubs/` of this user's private folder, [`envhub_core::private_dir`]: every
//! component of its path checked, as for the daemon's socket), and removes it when it leaves.
//! A client given no endpoint and no Zenoh config connects to the loopback endpoints listed
//! there (of hubs whose process is alive).
//!
//! Loopback is open to every user of the machine, so the folder also holds this user's local
//! credential ([`credential`]): a password only this user can read, which a default hub
//! checks every link into it against (Zenoh's user/password), and which this user's clients
//! present to their local hubs.

use envhub_core::private_dir;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

pub use envhub_core::env_vars::ENVHUB_LOCAL_HUBS;

fn uid() -> u32 {
    private_dir::uid()
}

/// The folder where this user's local hubs say where they listen: `ENVHUB_LOCAL_HUBS`, else
/// `hubs/` of this user's private folder; not made, not checked.
fn path() -> Result<PathBuf, String> {
    match std::env::var_os(ENVHUB_LOCAL_HUBS).filter(|d| !d.is_empty()) {
        Some(d) => Ok(PathBuf::from(d)),
        None => Ok(private_dir::base().map_err(|e| e.to_string())?.join("hubs")),
    }
}

/// [`path`], made where missing (mode 0700) and checked on every component.
pub fn dir() -> Result<PathBuf, String> {
    let dir = path()?;
    private_dir::ensure(&dir).map_err(|e| e.to_string())?;
    Ok(dir)
}

/// A hub's entry in the folder; removed when dropped.
#[derive(Debug)]
pub struct Published(PathBuf);

impl Drop for Published {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Writes that hub `name` listens on `endpoints` (mode 0600, in the private folder).
pub fn publish(name: &str, endpoints: &[String]) -> Result<Published, String> {
    let dir = dir()?;
    let pid = std::process::id();
    let path = dir.join(format!("{pid}.json"));
    let body = serde_json::json!({ "name": name, "endpoints": endpoints, "pid": pid }).to_string();
    write_private(&path, &body, true)?;
    Ok(Published(path))
}

/// The user name in this user's local credential.
pub const LOCAL_USER: &str = "envhub";

/// This user's credential for the local hubs: a password only this user can read, and the
/// Zenoh user/password dictionary a local hub checks links into it against.
#[derive(Clone, Debug)]
pub struct Credential {
    /// The password (64 hex digits, from the OS's random source).
    pub password: String,
    /// `envhub:<password>`, the hub's `transport/auth/usrpwd/dictionary_file`.
    pub dictionary: PathBuf,
}

/// This user's local credential, made on first need in the private folder (0600 files, in a
/// folder only this user can enter), so only this user's processes can present it.
pub fn credential() -> Result<Credential, String> {
    let dir = dir()?;
    let secret = dir.join("credential");
    let dictionary = dir.join("usrpwd");
    let password = match read_private(&secret)? {
        Some(p) => p,
        None => {
            let mut bytes = [0u8; 32];
            std::io::Read::read_exact(
                &mut std::fs::File::open("/dev/urandom")
                    .map_err(|e| format!("cannot open /dev/urandom: {e}"))?,
                &mut bytes,
            )
            .map_err(|e| format!("cannot read /dev/urandom: {e}"))?;
            let made: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
            // Two processes may make it at once: the first link wins and both read it back.
            write_private(&secret, &made, false)?;
            read_private(&secret)?.ok_or_else(|| format!("`{}` vanished", secret.display()))?
        }
    };
    let line = format!("{LOCAL_USER}:{password}\n");
    if read_private(&dictionary)?.as_deref() != Some(line.trim_end()) {
        write_private(&dictionary, &line, true)?;
    }
    Ok(Credential {
        password,
        dictionary,
    })
}

/// A file of this user that no one else can read, trimmed; `None` when there is none.
fn read_private(path: &Path) -> Result<Option<String>, String> {
    match private_dir::read_file(path, 4096) {
        Ok(body) => Ok(body.map(|b| String::from_utf8_lossy(&b).trim().to_string())),
        Err(e) => Err(format!("cannot read `{}`: {e}", path.display())),
    }
}

/// Writes `path` (mode 0600) whole through a fresh temporary file (`O_EXCL|O_NOFOLLOW`, a
/// random name): renamed over it (`replace`), or linked to it only where there is none yet
/// (a file another process made first stays).
fn write_private(path: &Path, body: &str, replace: bool) -> Result<(), String> {
    private_dir::write_file(path, body.as_bytes(), 0o600, replace)
        .map(drop)
        .map_err(|e| format!("cannot write `{}`: {e}", path.display()))
}

fn alive(pid: i32) -> bool {
    // SAFETY: signal 0 only checks that the process exists.
    pid > 0
        && (unsafe { libc::kill(pid, 0) } == 0
            || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM))
}

/// The loopback endpoints of this user's live local hubs, sorted. A folder that is not this
/// user's alone is ignored (with a warning): another user could list endpoints in it.
pub fn endpoints() -> Vec<String> {
    let dir = match path() {
        Ok(dir) if dir.exists() => dir,
        Ok(_) => return Vec::new(),
        Err(e) => {
            tracing::debug!("no local hubs: {e}");
            return Vec::new();
        }
    };
    if let Err(e) = private_dir::check(&dir) {
        tracing::warn!("local hubs ignored: {e}");
        return Vec::new();
    }
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut found: Vec<String> = entries
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().ends_with(".json"))
        .filter_map(|e| {
            let meta = e.metadata().ok()?;
            if meta.uid() != uid() || meta.len() > 4096 {
                return None;
            }
            let v: serde_json::Value =
                serde_json::from_slice(&std::fs::read(e.path()).ok()?).ok()?;
            let pid = i32::try_from(v["pid"].as_u64()?).ok()?;
            if !alive(pid) {
                let _ = std::fs::remove_file(e.path());
                return None;
            }
            let listed = v["endpoints"].as_array()?;
            let endpoints: Vec<String> = listed
                .iter()
                .filter_map(|e| e.as_str())
                .filter(|e| listable(e, &dir))
                .map(String::from)
                .collect();
            Some(endpoints)
        })
        .flatten()
        .collect();
    found.sort();
    found.dedup();
    found
}

/// The longest socket path a Unix socket takes (`sun_path`'s 108 bytes, less the NUL).
const MAX_SOCKET_PATH: usize = 107;

/// The Unix-socket endpoint of this process's hub in the folder of local hubs
/// (`unixsock-stream/<folder>/<pid>.sock`): only this user can reach a socket there (the
/// folder is 0700), so no other user's connections can crowd its links out. None where the
/// folder cannot be made or the path is too long for a socket (a hub then listens on a
/// loopback TCP port).
pub(crate) fn socket_endpoint() -> Option<String> {
    let dir = match dir() {
        Ok(dir) => dir,
        Err(e) => {
            tracing::debug!("no Unix socket for this hub: {e}");
            return None;
        }
    };
    let path = dir.join(format!("{}.sock", std::process::id()));
    let path = path.to_str()?;
    if path.len() > MAX_SOCKET_PATH {
        tracing::info!(
            path,
            "the folder of local hubs is too deep for a Unix socket ({MAX_SOCKET_PATH} bytes): \
             this hub listens on a loopback TCP port"
        );
        return None;
    }
    Some(format!("{}/{path}", crate::endpoint::UNIX_SOCKET))
}

/// Whether a listed endpoint may be connected to: a loopback TCP endpoint, or a Unix socket
/// in the folder of local hubs itself (where only this user can have made it).
fn listable(endpoint: &str, dir: &Path) -> bool {
    match crate::endpoint::unix_socket_path(endpoint) {
        Some(path) => Path::new(path).parent() == Some(dir),
        None => crate::endpoint::is_loopback(endpoint),
    }
}

/// A free loopback TCP port (for a hub's listener, so it can say which it is).
pub(crate) fn free_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn a_published_hub_is_listed_until_it_is_dropped_and_only_loopback_counts() {
        let dir = std::env::temp_dir().join(format!("envhub-local-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        // SAFETY: this test alone reads the variable in this process.
        unsafe { std::env::set_var(ENVHUB_LOCAL_HUBS, &dir) };
        let hub = publish("a", &["tcp/127.0.0.1:17001".to_string()]).unwrap();
        assert_eq!(endpoints(), vec!["tcp/127.0.0.1:17001".to_string()]);
        let mode = std::fs::metadata(&dir).unwrap().mode() & 0o777;
        assert_eq!(mode, 0o700);
        // A dead process's entry and a non-loopback endpoint are not listed.
        std::fs::write(
            dir.join("999999999.json"),
            r#"{"name":"x","endpoints":["tcp/127.0.0.1:1"],"pid":999999999}"#,
        )
        .unwrap();
        std::fs::write(
            dir.join("1.json"),
            r#"{"name":"y","endpoints":["tcp/192.0.2.7:7447"],"pid":1}"#,
        )
        .unwrap();
        assert_eq!(endpoints(), vec!["tcp/127.0.0.1:17001".to_string()]);
        // A Unix socket counts only in the folder itself.
        let inside = format!("unixsock-stream/{}/2.sock", dir.display());
        std::fs::write(
            dir.join(format!("{}.json", std::process::id() + 1)),
            serde_json::json!({"name": "u", "pid": std::process::id(),
                "endpoints": [inside, "unixsock-stream//tmp/elsewhere.sock"]})
            .to_string(),
        )
        .unwrap();
        assert_eq!(
            endpoints(),
            vec!["tcp/127.0.0.1:17001".to_string(), inside.clone()]
        );
        assert_eq!(
            socket_endpoint(),
            Some(format!(
                "unixsock-stream/{}/{}.sock",
                dir.display(),
                std::process::id()
            ))
        );
        std::fs::remove_file(dir.join(format!("{}.json", std::process::id() + 1))).unwrap();
        drop(hub);
        assert!(endpoints().is_empty());
        // A folder others may enter is not believed.
        let _again = publish("a", &["tcp/127.0.0.1:17001".to_string()]).unwrap();
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).unwrap();
        assert!(endpoints().is_empty());
        let e = publish("b", &[]).unwrap_err();
        assert!(
            e.contains(&format!("`{}` has mode 777", dir.display())),
            "{e}"
        );
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).unwrap();

        // The credential's files: a link planted in the place of either is refused, naming
        // it, and never read or written through.
        let victim = dir.with_extension("victim");
        std::fs::write(&victim, "precious").unwrap();
        for name in ["usrpwd", "credential"] {
            let _ = std::fs::remove_file(dir.join(name));
            std::os::unix::fs::symlink(&victim, dir.join(name)).unwrap();
            let e = credential().unwrap_err();
            assert!(e.contains(name) && e.contains("symbolic link"), "{e}");
            assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
            std::fs::remove_file(dir.join(name)).unwrap();
        }
        let made = credential().unwrap();
        let dictionary = std::fs::read_to_string(&made.dictionary).unwrap();
        assert_eq!(dictionary, format!("{LOCAL_USER}:{}\n", made.password));
        assert_eq!(credential().unwrap().password, made.password);
        unsafe { std::env::remove_var(ENVHUB_LOCAL_HUBS) };
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_file(&victim);
    }
}
