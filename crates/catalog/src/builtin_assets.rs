//! The built-in catalog's model files (`configs/assets/`), compiled into the binary and
//! written on first use to a folder of this user's private folder
//! ([`envhub_core::private_dir`]), where the catalog's relative `asset_path`s point. An
//! installed binary (a wheel, `cargo install`) has no source tree to point into, and must
//! carry no path of the machine it was built on; and a folder of the shared temporary
//! directory could be made first by another user, who would then choose the models.

use envhub_core::private_dir;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Every file the built-in catalog names, relative to its folder. Adding one is one line.
const FILES: &[(&str, &str)] = &[(
    "assets/planar_walker.xml",
    include_str!("../../../configs/assets/planar_walker.xml"),
)];

/// The folder the built-in catalog's relative paths resolve against, its files written, or
/// why there is none (the private folder is missing, not this user's alone, or unwritable).
/// Named by version and content, so a changed file gets a new folder and no process
/// rewrites another's.
pub(crate) fn builtin_dir() -> Result<PathBuf, String> {
    static DIR: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    DIR.get_or_init(|| {
        let name = format!(
            "configs-{}-{:016x}",
            env!("CARGO_PKG_VERSION"),
            fingerprint()
        );
        let dir = private_dir::runtime_dir(&name).map_err(|e| e.to_string())?;
        write_all(&dir).map_err(|e| {
            format!(
                "cannot write the built-in catalog's model files to `{}`: {e}",
                dir.display()
            )
        })?;
        Ok(dir)
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

/// Writes each missing or changed file whole (a fresh temporary file renamed into place), in
/// subfolders checked like the folder itself.
fn write_all(dir: &Path) -> Result<(), String> {
    for (name, text) in FILES {
        let path = dir.join(name);
        let parent = path.parent().unwrap_or(dir);
        private_dir::ensure(parent).map_err(|e| e.to_string())?;
        let have = private_dir::read_file(&path, text.len() as u64 + 1);
        if have.is_ok_and(|have| have.as_deref() == Some(text.as_bytes())) {
            continue;
        }
        private_dir::write_file(&path, text.as_bytes(), 0o600, true).map_err(|e| e.to_string())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_are_written_once_with_their_content() {
        let dir = builtin_dir().unwrap();
        for (name, text) in FILES {
            assert_eq!(std::fs::read_to_string(dir.join(name)).unwrap(), *text);
        }
        assert_eq!(builtin_dir().unwrap(), dir);
        // Rewritten where a file was changed or replaced by something else.
        let path = dir.join(FILES[0].0);
        std::fs::remove_file(&path).unwrap();
        std::os::unix::fs::symlink("/dev/null", &path).unwrap();
        write_all(&dir).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), FILES[0].1);
    }
}
