//! Who is at the other end of a session: a hub's static identity key (kept in its user's
//! private config folder) and the identities this user's clients have pinned for hub names
//! (`known_hubs`, trust on first use, as ssh's `known_hosts`). See
//! [`envhub_protocol::handshake`] for the exchange that uses them.
//!
//! Both files live in `$XDG_CONFIG_HOME/envhub` (else `~/.config/envhub`), a folder created
//! with mode 0700 and refused, naming it, when it is a link, another user's, or open to
//! others. The key is written once, 0600, through a temp file opened with
//! `O_CREAT|O_EXCL|O_NOFOLLOW` and hard-linked into place (two hubs starting at once keep
//! the first key); pins are appended, 0600, never through a link.

use envhub_protocol::HubError;
use envhub_protocol::handshake::Identity;
use std::io::Write;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// The file of a hub's identity key (PKCS#8, Ed25519); default: `hub_identity.pk8` in the
/// config folder.
pub const ENVHUB_HUB_KEY: &str = "ENVHUB_HUB_KEY";
/// The file of the hub identities this user's clients pinned; default: `known_hubs` in the
/// config folder.
pub const ENVHUB_KNOWN_HUBS: &str = "ENVHUB_KNOWN_HUBS";

fn uid() -> u32 {
    // SAFETY: getuid has no preconditions.
    unsafe { libc::getuid() }
}

/// envhub's folder in this user's config folder.
fn config_dir() -> Result<PathBuf, String> {
    let base = std::env::var_os("XDG_CONFIG_HOME")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|d| !d.is_empty())
                .map(|h| PathBuf::from(h).join(".config"))
        })
        .ok_or("neither `XDG_CONFIG_HOME` nor `HOME` is set")?;
    Ok(base.join("envhub"))
}

/// The file `var` names, else `name` in the config folder.
fn file(var: &str, name: &str) -> Result<PathBuf, String> {
    match std::env::var_os(var).filter(|v| !v.is_empty()) {
        Some(path) => Ok(PathBuf::from(path)),
        None => Ok(config_dir()?.join(name)),
    }
}

/// Creates `dir` (0700) if missing, and checks it is a folder of this user closed to others.
fn private_dir(dir: &Path) -> Result<(), String> {
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent)
            .map_err(|e| format!("cannot create `{}`: {e}", parent.display()))?;
    }
    match std::fs::create_dir(dir) {
        Ok(()) => envhub_core::private_dir::set_dir_mode(dir, 0o700)
            .map_err(|e| format!("cannot make `{}` private: {e}", dir.display()))?,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(format!("cannot create `{}`: {e}", dir.display())),
    }
    let meta = std::fs::symlink_metadata(dir)
        .map_err(|e| format!("cannot inspect `{}`: {e}", dir.display()))?;
    if !meta.is_dir() || meta.uid() != uid() || meta.mode() & 0o077 != 0 {
        return Err(format!(
            "`{}` is not a folder of this user closed to others (uid {}, mode {:o}); fix: \
             `chmod 700` it if it is yours, else remove it",
            dir.display(),
            meta.uid(),
            meta.mode() & 0o777
        ));
    }
    Ok(())
}

/// Reads `path` if it exists: a file (not a link) of this user that others cannot read.
fn read_private(path: &Path) -> Result<Option<Vec<u8>>, String> {
    let mut f = match std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)
    {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("cannot open `{}`: {e}", path.display())),
    };
    let meta = f
        .metadata()
        .map_err(|e| format!("cannot inspect `{}`: {e}", path.display()))?;
    if !meta.is_file() || meta.uid() != uid() || meta.mode() & 0o077 != 0 {
        return Err(format!(
            "`{}` is not a file of this user closed to others (uid {}, mode {:o}); fix: \
             `chmod 600` it if it is yours, else remove it",
            path.display(),
            meta.uid(),
            meta.mode() & 0o777
        ));
    }
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut f, &mut bytes)
        .map_err(|e| format!("cannot read `{}`: {e}", path.display()))?;
    Ok(Some(bytes))
}

fn folder_of(path: &Path) -> &Path {
    path.parent().unwrap_or(Path::new("."))
}

/// This user's hub identity (made and stored on first use).
pub fn hub_identity() -> Result<Identity, HubError> {
    let failed = |reason: String| HubError::Network {
        reason: format!("cannot use this hub's identity key: {reason}"),
        hint: format!(
            "the key is `{ENVHUB_HUB_KEY}`, else `hub_identity.pk8` in `$XDG_CONFIG_HOME/envhub` \
             (`~/.config/envhub`); its folder must be this user's, mode 0700"
        ),
    };
    let path = file(ENVHUB_HUB_KEY, "hub_identity.pk8").map_err(failed)?;
    private_dir(folder_of(&path)).map_err(failed)?;
    let stored = match read_private(&path).map_err(failed)? {
        Some(bytes) => bytes,
        None => {
            let pkcs8 = Identity::generate_pkcs8().map_err(failed)?;
            let tmp = path.with_extension(format!("tmp{}", std::process::id()));
            let mut f = std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .mode(0o600)
                .custom_flags(libc::O_NOFOLLOW)
                .open(&tmp)
                .map_err(|e| failed(format!("cannot create `{}`: {e}", tmp.display())))?;
            // 0600 exactly, whatever the umask.
            let written = f
                .set_permissions(std::fs::Permissions::from_mode(0o600))
                .and_then(|()| f.write_all(&pkcs8))
                .and_then(|()| f.sync_all());
            // A hub starting at the same time may have stored its key first: that one wins.
            let linked = written.and_then(|()| std::fs::hard_link(&tmp, &path));
            let _ = std::fs::remove_file(&tmp);
            match linked {
                Ok(()) => pkcs8,
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => read_private(&path)
                    .map_err(failed)?
                    .ok_or_else(|| failed(format!("`{}` vanished", path.display())))?,
                Err(e) => {
                    return Err(failed(format!("cannot store `{}`: {e}", path.display())));
                }
            }
        }
    };
    Identity::from_pkcs8(&stored).map_err(|e| failed(format!("`{}`: {e}", path.display())))
}

/// The pins of hub identities this user's clients keep.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct KnownHubs {
    path: Option<PathBuf>,
}

impl KnownHubs {
    /// The file `ENVHUB_KNOWN_HUBS` names, else `known_hubs` in the config folder; `given`
    /// (`known_hubs:` in `envhub.yaml`'s `zenoh:`) first.
    pub fn new(given: Option<&Path>) -> KnownHubs {
        KnownHubs {
            path: given
                .map(Path::to_path_buf)
                .or_else(|| file(ENVHUB_KNOWN_HUBS, "known_hubs").ok()),
        }
    }

    /// Checks hub `hub`'s identity `identity` (64 hex digits) against its pin; pins it if it
    /// has none (trust on first use). A different identity is an error naming the hub, both
    /// keys and the file.
    pub fn check(&self, hub: &str, identity: &str) -> Result<(), HubError> {
        let failed = |reason: String| HubError::Network {
            reason: format!("cannot check hub `{hub}`'s identity: {reason}"),
            hint: format!(
                "the pins are `{ENVHUB_KNOWN_HUBS}`, else `known_hubs` in \
                 `$XDG_CONFIG_HOME/envhub` (`~/.config/envhub`)"
            ),
        };
        let path = self
            .path
            .clone()
            .ok_or_else(|| failed("no config folder (`HOME` is not set)".into()))?;
        for attempt in 0..2 {
            let text = read_private(&path).map_err(failed)?.unwrap_or_default();
            let pinned = String::from_utf8_lossy(&text)
                .lines()
                .filter_map(|l| {
                    let mut words = l.split_whitespace();
                    Some((words.next()?.to_string(), words.next()?.to_string()))
                })
                .find(|(name, _)| name == hub)
                .map(|(_, key)| key);
            match pinned {
                Some(key) if key == identity => return Ok(()),
                Some(key) => {
                    return Err(HubError::Refused {
                        hub: hub.to_string(),
                        reason: format!(
                            "its identity key is {identity}, but `{}` pins hub `{hub}` to {key}: \
                             another process may be answering in its name",
                            path.display()
                        ),
                        hint: format!(
                            "if the hub's key changed on purpose (a new machine, its key file \
                             removed), delete the line `{hub} {key}` from `{}`",
                            path.display()
                        ),
                    });
                }
                None if attempt == 0 => {
                    private_dir(folder_of(&path)).map_err(failed)?;
                    let mut f = std::fs::OpenOptions::new()
                        .append(true)
                        .create(true)
                        .mode(0o600)
                        .custom_flags(libc::O_NOFOLLOW)
                        .open(&path)
                        .map_err(|e| failed(format!("cannot open `{}`: {e}", path.display())))?;
                    f.set_permissions(std::fs::Permissions::from_mode(0o600))
                        .map_err(|e| failed(format!("cannot chmod `{}`: {e}", path.display())))?;
                    // One write of one line: appends of clients pinning at once do not mix.
                    f.write_all(format!("{hub} {identity}\n").as_bytes())
                        .map_err(|e| failed(format!("cannot write `{}`: {e}", path.display())))?;
                    tracing::info!(hub, identity, file = %path.display(), "pinned a new hub's identity");
                }
                None => return Err(failed(format!("`{}` did not keep the pin", path.display()))),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hub_is_pinned_on_first_use_and_another_key_is_refused_naming_the_file() {
        let dir = std::env::temp_dir().join(format!("envhub-known-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("known_hubs");
        let known = KnownHubs::new(Some(&path));
        let (a, b) = ("aa".repeat(32), "bb".repeat(32));
        known.check("lab", &a).expect("first use pins");
        known.check("lab", &a).expect("the same key again");
        known.check("other", &b).expect("another hub, another pin");
        let err = known.check("lab", &b).unwrap_err().to_string();
        assert!(
            err.contains("lab") && err.contains(&path.display().to_string()) && err.contains(&a),
            "{err}"
        );
        let mode = std::fs::metadata(&path).unwrap().mode() & 0o777;
        assert_eq!(mode, 0o600);
        // A pin file others may write is not believed.
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o666)).unwrap();
        let err = known.check("lab", &a).unwrap_err().to_string();
        assert!(err.contains("closed to others"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
