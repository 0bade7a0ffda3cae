//! The built-in catalog's model files (`configs/assets/`), compiled into the binary and
//! written to a folder of the temporary directory on first use, where the catalog's relative
//! `asset_path`s point. An installed binary (a wheel, `cargo install`) has no source tree to
//! point into, and must carry no path of the machine it was built on.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Every file the built-in catalog names, relative to its folder. Adding one is one line.
const FILES: &[(&str, &str)] = &[(
    "assets/planar_walker.xml",
    include_str!("../../configs/assets/planar_walker.xml"),
)];

/// The folder the built-in catalog's relative paths resolve against, its files written.
/// Named by user, version and content, so a changed file gets a new folder and no process
/// rewrites another's; a failure to write is logged, and the env that needs the file then
/// reports it missing.
pub(crate) fn builtin_dir() -> PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // SAFETY: getuid has no preconditions and cannot fail.
        let uid = unsafe { libc::getuid() };
        let dir = std::env::temp_dir().join(format!(
            "envhub-{uid}-configs-{}-{:016x}",
            env!("CARGO_PKG_VERSION"),
            fingerprint()
        ));
        if let Err(e) = write_all(&dir) {
            tracing::warn!(
                "cannot write the built-in catalog's model files to `{}`: {e}",
                dir.display()
            );
        }
        dir
    })
    .clone()
}

/// FNV-1a over names and contents (stable across builds, unlike `DefaultHasher`).
fn fingerprint() -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for (name, text) in FILES {
        for b in name.bytes().chain([0]).chain(text.bytes()).chain([0]) {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// Writes each missing file through a temporary name and a rename, so a concurrent process
/// never reads a partial file.
fn write_all(dir: &Path) -> std::io::Result<()> {
    for (name, text) in FILES {
        let path = dir.join(name);
        if std::fs::read(&path).is_ok_and(|have| have == text.as_bytes()) {
            continue;
        }
        let parent = path.parent().unwrap_or(dir);
        std::fs::create_dir_all(parent)?;
        let tmp = parent.join(format!(".{}.{}", std::process::id(), fingerprint()));
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, &path)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_are_written_once_with_their_content() {
        let dir = builtin_dir();
        for (name, text) in FILES {
            assert_eq!(std::fs::read_to_string(dir.join(name)).unwrap(), *text);
        }
        assert_eq!(builtin_dir(), dir);
    }
}
