//! The folder where envhub keeps what it writes on its own (the built-in model files, this
//! machine's hub entries and the local credential, the daemon's socket, overlay and scratch
//! folders), and how files are written into it.
//!
//! A predictable name in a shared temporary folder (`/tmp/envhub-<uid>`) can be made first by
//! another user of the machine, who then decides what is read from it and where writes
//! through it land. So the folder is `$XDG_RUNTIME_DIR/envhub`, else
//! `$XDG_CACHE_HOME/envhub/run`, else `~/.cache/envhub/run`, and before it is used every
//! component of its path is checked with `lstat`: owned by this user or root, writable by no
//! one else (unless sticky, as `/tmp` is), and the folder itself this user's, closed to
//! others and not a link. Missing components are made with mode 0700 (exactly: set through a
//! descriptor, not left to the umask). A folder that fails
//! is an error naming it, what is wrong and the fix; it is never used.
//!
//! Files are written through a temporary file of a random name, opened with
//! `O_CREAT|O_EXCL|O_NOFOLLOW`, then renamed (or hard-linked) into place, so neither a
//! planted link nor a concurrent reader sees anything but a whole file of this user's.

use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Component, Path, PathBuf};

/// This process's real uid.
pub fn uid() -> u32 {
    // SAFETY: getuid has no preconditions and cannot fail.
    unsafe { libc::getuid() }
}

/// A folder envhub cannot trust, and why.
#[derive(Debug, thiserror::Error)]
pub enum PrivateDirError {
    /// No folder of this user's is named by the environment.
    #[error(
        "no folder of this user's for envhub's files: `XDG_RUNTIME_DIR`, `XDG_CACHE_HOME` and `HOME` are all unset\nhint: set `XDG_RUNTIME_DIR` to a folder only you can enter"
    )]
    NoHome,
    /// A component is a symbolic link where envhub follows none.
    #[error(
        "`{}` is a symbolic link (owned by uid {owner}); envhub does not write through links it does not trust\nhint: remove the link (`rm {}`), or set `XDG_RUNTIME_DIR` to a folder of your own", path.display(), path.display()
    )]
    Symlink {
        /// The link.
        path: PathBuf,
        /// Its owner.
        owner: u32,
    },
    /// A component is not a folder.
    #[error("`{}` is not a folder\nhint: remove it, or set `XDG_RUNTIME_DIR` to a folder of your own", path.display())]
    NotDir {
        /// The component.
        path: PathBuf,
    },
    /// A component belongs to another user.
    #[error(
        "`{}` belongs to uid {owner}, not to this user (uid {uid}) or root; another user may have made it first\nhint: remove it (as root: `rm -r {}`), or set `XDG_RUNTIME_DIR` to a folder of your own", path.display(), path.display()
    )]
    Owner {
        /// The component.
        path: PathBuf,
        /// Its owner.
        owner: u32,
        /// This process's uid.
        uid: u32,
    },
    /// A component others may write in (or, for envhub's own folder, enter).
    #[error(
        "`{}` has mode {mode:o}: other users could {} it\nhint: `chmod {} {}`", path.display(),
        if *.own { "enter or change what is in" } else { "replace what is in" },
        if *.own { "700" } else { "go-w" }, path.display()
    )]
    Mode {
        /// The component.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
        /// Whether it is envhub's own folder (which must be closed to others), not an
        /// ancestor (which must only be closed to their writes).
        own: bool,
    },
    /// The file system refused to inspect or make a component.
    #[error("cannot {action} `{}`: {source}\nhint: set `XDG_RUNTIME_DIR` to a folder only you can enter", path.display())]
    Io {
        /// What was tried (`inspect`, `create`).
        action: &'static str,
        /// The component.
        path: PathBuf,
        /// Why it failed.
        #[source]
        source: std::io::Error,
    },
}

/// This user's private folder for envhub (see the module doc), made and checked; `sub`
/// names a folder inside it (made and checked too), or is empty for the folder itself.
pub fn runtime_dir(sub: &str) -> Result<PathBuf, PrivateDirError> {
    let base = base()?;
    ensure(&base)?;
    if sub.is_empty() {
        return Ok(base);
    }
    let dir = base.join(sub);
    ensure(&dir)?;
    Ok(dir)
}

/// Where this user's private folder for envhub is, made or not, checked or not: for a reader
/// that should neither make it nor trust it before [`check`].
pub fn base() -> Result<PathBuf, PrivateDirError> {
    let var = |name: &str| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    Ok(match var("XDG_RUNTIME_DIR") {
        Some(run) => run.join("envhub"),
        None => var("XDG_CACHE_HOME")
            .or_else(|| var("HOME").map(|h| h.join(".cache")))
            .ok_or(PrivateDirError::NoHome)?
            .join("envhub")
            .join("run"),
    })
}

/// Makes `dir`'s missing components (mode 0700) and checks every component (see the module
/// doc): `dir` itself must be this user's, a real folder, and closed to everyone else.
pub fn ensure(dir: &Path) -> Result<(), PrivateDirError> {
    walk(dir, true)
}

/// [`ensure`] without making anything: for a reader, which must not trust a folder it did
/// not find private either.
pub fn check(dir: &Path) -> Result<(), PrivateDirError> {
    walk(dir, false)
}

fn walk(dir: &Path, create: bool) -> Result<(), PrivateDirError> {
    let io = |action, path: &Path| {
        let path = path.to_path_buf();
        move |source| PrivateDirError::Io {
            action,
            path,
            source,
        }
    };
    let dir = if dir.is_absolute() {
        dir.to_path_buf()
    } else {
        std::env::current_dir()
            .map_err(io("find the current folder of", dir))?
            .join(dir)
    };
    let parts: Vec<Component> = dir.components().collect();
    let mut at = PathBuf::from("/");
    ancestor(
        &at,
        &std::fs::symlink_metadata(&at).map_err(io("inspect", &at))?,
    )?;
    for (i, part) in parts.iter().enumerate() {
        let name = match part {
            Component::Normal(name) => name,
            Component::ParentDir => {
                at.pop();
                continue;
            }
            _ => continue,
        };
        let last = i + 1 == parts.len();
        let next = at.join(name);
        let meta = match std::fs::symlink_metadata(&next) {
            Err(e) if create && e.kind() == std::io::ErrorKind::NotFound => {
                match std::fs::DirBuilder::new().mode(0o700).create(&next) {
                    Ok(()) => set_dir_mode(&next, 0o700).map_err(io("set the mode of", &next))?,
                    // Made by another process meanwhile: checked below like any other.
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                    Err(e) => return Err(io("create", &next)(e)),
                }
                std::fs::symlink_metadata(&next).map_err(io("inspect", &next))?
            }
            other => other.map_err(io("inspect", &next))?,
        };
        if meta.file_type().is_symlink() {
            // A link above envhub's folder is followed only when this user or root made
            // it, in a folder already found trusted; then its target's whole path is checked.
            if last || !trusted(meta.uid()) {
                return Err(PrivateDirError::Symlink {
                    path: next,
                    owner: meta.uid(),
                });
            }
            let target = std::fs::canonicalize(&next).map_err(io("resolve", &next))?;
            walk_resolved(&target)?;
            at = target;
            continue;
        }
        if last {
            own(&next, &meta)?;
        } else {
            ancestor(&next, &meta)?;
        }
        at = next;
    }
    Ok(())
}

/// Checks every component of a path without links (as `canonicalize` gives) as an ancestor.
fn walk_resolved(path: &Path) -> Result<(), PrivateDirError> {
    let mut at = PathBuf::new();
    for part in path.components() {
        at.push(part);
        let meta = std::fs::symlink_metadata(&at).map_err(|source| PrivateDirError::Io {
            action: "inspect",
            path: at.clone(),
            source,
        })?;
        if meta.file_type().is_symlink() {
            return Err(PrivateDirError::Symlink {
                path: at,
                owner: meta.uid(),
            });
        }
        ancestor(&at, &meta)?;
    }
    Ok(())
}

fn trusted(owner: u32) -> bool {
    owner == uid() || owner == 0
}

/// A folder above envhub's own: this user's or root's, and no one else may replace what is
/// in it (unless sticky: then no one else may rename or remove this user's entries).
fn ancestor(path: &Path, meta: &std::fs::Metadata) -> Result<(), PrivateDirError> {
    if !meta.is_dir() {
        return Err(PrivateDirError::NotDir {
            path: path.to_path_buf(),
        });
    }
    if !trusted(meta.uid()) {
        return Err(PrivateDirError::Owner {
            path: path.to_path_buf(),
            owner: meta.uid(),
            uid: uid(),
        });
    }
    if meta.mode() & 0o022 != 0 && meta.mode() & 0o1000 == 0 {
        return Err(PrivateDirError::Mode {
            path: path.to_path_buf(),
            mode: meta.mode() & 0o7777,
            own: false,
        });
    }
    Ok(())
}

/// envhub's own folder: a real folder of this user's that no one else may enter.
fn own(path: &Path, meta: &std::fs::Metadata) -> Result<(), PrivateDirError> {
    if !meta.is_dir() {
        return Err(PrivateDirError::NotDir {
            path: path.to_path_buf(),
        });
    }
    if meta.uid() != uid() {
        return Err(PrivateDirError::Owner {
            path: path.to_path_buf(),
            owner: meta.uid(),
            uid: uid(),
        });
    }
    if meta.mode() & 0o077 != 0 {
        return Err(PrivateDirError::Mode {
            path: path.to_path_buf(),
            mode: meta.mode() & 0o7777,
            own: true,
        });
    }
    Ok(())
}

/// A name no other process can guess: 64 random bits from the OS, in hex.
fn random_name() -> String {
    use rand::TryRngCore;
    let bits = rand::rngs::OsRng.try_next_u64().unwrap_or_else(|_| {
        // No OS randomness: O_EXCL still refuses a planted name; only a retry costs.
        (u64::from(std::process::id()) << 32)
            ^ u64::from(
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .unwrap_or_default()
                    .subsec_nanos(),
            )
    });
    format!("{bits:016x}")
}

/// Gives folder `dir` (just made by this process) mode `mode` exactly, whatever the umask:
/// through a descriptor opened with `O_NOFOLLOW|O_DIRECTORY`, so a link put in its place
/// meanwhile is refused, never followed.
pub fn set_dir_mode(dir: &Path, mode: u32) -> std::io::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(dir)?
        .set_permissions(std::fs::Permissions::from_mode(mode))
}

/// Writes `body` to `path` (mode `mode`) whole: through a fresh temporary file beside it
/// (random name, `O_CREAT|O_EXCL|O_NOFOLLOW`), then renamed over it (`replace`), or linked
/// to it only where there is none yet (a file another process made first stays; returns
/// whether this one was linked). `path`'s folder should be one [`ensure`] accepted.
pub fn write_file(path: &Path, body: &[u8], mode: u32, replace: bool) -> std::io::Result<bool> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    let mut tries = 0;
    let (tmp, mut file) = loop {
        let tmp = dir.join(format!(".{name}.{}.tmp", random_name()));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(mode)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(&tmp)
        {
            Ok(f) => break (tmp, f),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && tries < 8 => tries += 1,
            Err(e) => return Err(e),
        }
    };
    let done = (|| {
        // The mode exactly, not the mode under the umask (fchmod of the descriptor).
        use std::os::unix::fs::PermissionsExt;
        file.set_permissions(std::fs::Permissions::from_mode(mode))?;
        file.write_all(body)?;
        file.sync_all()?;
        if replace {
            std::fs::rename(&tmp, path)?;
            return Ok(true);
        }
        match std::fs::hard_link(&tmp, path) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(false),
            Err(e) => Err(e),
        }
    })();
    if !(replace && done.is_ok()) {
        let _ = std::fs::remove_file(&tmp);
    }
    done
}

/// Reads `path` if it is a regular file of this user's that no one else may read, of at
/// most `max` bytes (opened with `O_NOFOLLOW`: a link is refused); `None` when there is
/// none.
pub fn read_file(path: &Path, max: u64) -> std::io::Result<Option<Vec<u8>>> {
    use std::io::Read;
    let file = match std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC | libc::O_NONBLOCK)
        .open(path)
    {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) if e.raw_os_error() == Some(libc::ELOOP) => {
            return Err(std::io::Error::other(format!(
                "`{}` is a symbolic link",
                path.display()
            )));
        }
        Err(e) => return Err(e),
    };
    let meta = file.metadata()?;
    if !meta.is_file() || meta.uid() != uid() || meta.mode() & 0o077 != 0 || meta.len() > max {
        return Err(std::io::Error::other(format!(
            "`{}` is not a file of this user closed to others of at most {max} bytes (uid {}, mode {:o}, {} bytes)",
            path.display(),
            meta.uid(),
            meta.mode() & 0o777,
            meta.len()
        )));
    }
    let mut body = Vec::new();
    file.take(max + 1).read_to_end(&mut body)?;
    Ok(Some(body))
}

/// A fresh folder (mode 0700, a random name after `prefix`) inside `parent`, which should be
/// one [`ensure`] accepted: for scratch work that no other process may enter or predict.
pub fn fresh_dir(parent: &Path, prefix: &str) -> std::io::Result<PathBuf> {
    let mut tries = 0;
    loop {
        let dir = parent.join(format!("{prefix}{}", random_name()));
        match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
            Ok(()) => return set_dir_mode(&dir, 0o700).map(|()| dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && tries < 8 => tries += 1,
            Err(e) => return Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn scratch(tag: &str) -> PathBuf {
        let base = std::env::temp_dir().join(format!(
            "envhub-core-private-{tag}-{}-{}",
            std::process::id(),
            random_name()
        ));
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&base)
            .unwrap();
        base
    }

    fn chmod(path: &Path, mode: u32) {
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }

    #[test]
    fn missing_components_are_made_closed_and_an_open_one_is_refused_by_name() {
        let base = scratch("make");
        let dir = base.join("a").join("b");
        ensure(&dir).unwrap();
        for d in [base.join("a"), dir.clone()] {
            assert_eq!(std::fs::metadata(&d).unwrap().mode() & 0o777, 0o700);
        }
        check(&dir).unwrap();
        // envhub's own folder open to others: refused, named, with the fix.
        chmod(&dir, 0o750);
        let e = check(&dir).unwrap_err().to_string();
        assert!(
            e.contains(&format!("`{}` has mode 750", dir.display())),
            "{e}"
        );
        assert!(e.contains("hint: `chmod 700"), "{e}");
        chmod(&dir, 0o700);
        // An ancestor others may write in: refused; a sticky one (as `/tmp`) is fine.
        chmod(&base.join("a"), 0o777);
        let e = check(&dir).unwrap_err().to_string();
        assert!(e.contains("has mode 777") && e.contains("go-w"), "{e}");
        chmod(&base.join("a"), 0o1777);
        check(&dir).unwrap();
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn a_link_as_the_folder_or_a_file_in_its_place_is_refused() {
        let base = scratch("link");
        let real = base.join("real");
        ensure(&real).unwrap();
        let link = base.join("link");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let e = ensure(&link).unwrap_err();
        assert!(matches!(e, PrivateDirError::Symlink { .. }), "{e}");
        assert!(e.to_string().contains("symbolic link"), "{e}");
        // A link above the folder, made by this user in a trusted folder, is followed and
        // its target checked.
        ensure(&link.join("inner")).unwrap();
        assert!(real.join("inner").is_dir());
        std::fs::write(base.join("file"), "x").unwrap();
        let e = ensure(&base.join("file")).unwrap_err();
        assert!(matches!(e, PrivateDirError::NotDir { .. }), "{e}");
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn files_are_written_whole_never_through_a_planted_link() {
        let base = scratch("write");
        let target = base.join("victim");
        std::fs::write(&target, "precious").unwrap();
        let path = base.join("entry");
        // A link in the entry's place is replaced, not written through.
        std::os::unix::fs::symlink(&target, &path).unwrap();
        assert!(write_file(&path, b"new", 0o600, true).unwrap());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "precious");
        assert_eq!(read_file(&path, 64).unwrap().unwrap(), b"new");
        assert_eq!(std::fs::metadata(&path).unwrap().mode() & 0o777, 0o600);
        // Without `replace`, a file made first stays.
        assert!(!write_file(&path, b"other", 0o600, false).unwrap());
        assert_eq!(read_file(&path, 64).unwrap().unwrap(), b"new");
        // No temporary file is left behind.
        let names: Vec<_> = std::fs::read_dir(&base)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        assert!(names.iter().all(|n| !n.ends_with(".tmp")), "{names:?}");
        // A reader refuses a link, a file others may read, and one too large.
        let link = base.join("link");
        std::os::unix::fs::symlink(&path, &link).unwrap();
        assert!(read_file(&link, 64).is_err());
        chmod(&path, 0o644);
        assert!(read_file(&path, 64).is_err());
        chmod(&path, 0o600);
        assert!(read_file(&path, 2).is_err());
        assert!(read_file(&base.join("none"), 64).unwrap().is_none());
        std::fs::remove_dir_all(&base).unwrap();
    }

    /// Folders and files get their modes exactly under any umask: the process's umask is
    /// the process's, so this test sets it in a process of its own (this test binary run
    /// again) and checks what that made.
    #[test]
    fn modes_are_exact_under_any_umask() {
        const MADE_UNDER_UMASK: &str = "ENVHUB_TEST_MADE_UNDER_UMASK";
        if let Ok(base) = std::env::var(MADE_UNDER_UMASK) {
            let base = PathBuf::from(base);
            // SAFETY: umask has no preconditions; this process runs this test alone.
            unsafe { libc::umask(0o277) };
            ensure(&base.join("a").join("b")).unwrap();
            fresh_dir(&base, "s-").unwrap();
            write_file(&base.join("a").join("f"), b"x", 0o640, true).unwrap();
            return;
        }
        let base = scratch("umask");
        let status = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "private_dir::tests::modes_are_exact_under_any_umask",
                "--nocapture",
            ])
            .env(MADE_UNDER_UMASK, &base)
            .status()
            .unwrap();
        assert!(status.success(), "the child under umask 0277 failed");
        let mode = |p: &Path| std::fs::metadata(p).unwrap().mode() & 0o777;
        assert_eq!(mode(&base.join("a")), 0o700);
        assert_eq!(mode(&base.join("a").join("b")), 0o700);
        assert_eq!(mode(&base.join("a").join("f")), 0o640);
        let fresh = std::fs::read_dir(&base)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.file_name().unwrap().to_string_lossy().starts_with("s-"))
            .expect("the fresh folder");
        assert_eq!(mode(&fresh), 0o700);
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn fresh_folders_are_new_closed_and_distinct() {
        let base = scratch("fresh");
        let a = fresh_dir(&base, "s-").unwrap();
        let b = fresh_dir(&base, "s-").unwrap();
        assert_ne!(a, b);
        assert_eq!(std::fs::metadata(&a).unwrap().mode() & 0o777, 0o700);
        std::fs::remove_dir_all(&base).unwrap();
    }
}
