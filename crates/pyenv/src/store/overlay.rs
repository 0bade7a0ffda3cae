//! The overlay: one folder per install (a checkout, a wheel) that its workers put first on
//! `sys.path`, holding one link per package (`envhub` → that install's package folder).
//! Keyed by the packages' paths, so no install re-points a link another one's workers
//! follow; in the cache folder, or in a private folder where the cache is read-only.

use super::{INSTALLS, Store};
use crate::error::{PyEnvError, io};
use envhub_catalog::fnv1a64;
use std::path::{Path, PathBuf};

impl Store {
    /// This install's overlay: the folder its workers put first on `sys.path`, holding one
    /// link per package (`envhub` → this install's package folder) and nothing else. Keyed
    /// by the packages' paths, so each install (a checkout, a wheel) has its own, and none
    /// re-points a link another one's workers follow. In `<root>/.installs/`, or, where the
    /// cache is read-only, in a folder only this user can write.
    pub fn overlay(&self, name: &str) -> Result<PathBuf, PyEnvError> {
        if let Some(dir) = self.overlay.get() {
            return Ok(dir.clone());
        }
        let text: String = self
            .packages
            .iter()
            .map(|p| format!("{}\n", p.display()))
            .collect();
        let key = format!("{:016x}", fnv1a64(text.as_bytes()));
        let in_cache = self.root.join(INSTALLS).join(&key);
        let dir = match fill_overlay(&in_cache, &self.packages) {
            Ok(()) => in_cache,
            Err(e) => {
                let base = private_folder().map_err(io(
                    name,
                    "make a private folder for",
                    Path::new("the overlay"),
                ))?;
                let elsewhere = base.join(&key);
                tracing::debug!(
                    "cannot make the overlay `{}` ({e}); using `{}`",
                    in_cache.display(),
                    elsewhere.display()
                );
                fill_overlay(&elsewhere, &self.packages).map_err(io(
                    name,
                    "make the overlay folder",
                    &elsewhere,
                ))?;
                elsewhere
            }
        };
        Ok(self.overlay.get_or_init(|| dir).clone())
    }
}

/// A folder only this user can write, for overlays when the cache is read-only:
/// `installs/` of this user's private folder ([`envhub_core::private_dir`]),
/// made with mode 0700 and refused, naming what is wrong, unless every component of its path
/// is this user's or root's and closed to others' writes (another user could otherwise point
/// the worker's `envhub` at their code).
fn private_folder() -> std::io::Result<PathBuf> {
    envhub_core::private_dir::runtime_dir("installs").map_err(std::io::Error::other)
}

/// Makes `dir` hold one link per package folder (`envhub` → the package), where it does
/// not already; a link is replaced atomically (made beside it, renamed over it).
fn fill_overlay(dir: &Path, packages: &[PathBuf]) -> std::io::Result<()> {
    for package in packages {
        let Some(file_name) = package.file_name() else {
            continue;
        };
        let link = dir.join(file_name);
        if std::fs::read_link(&link).is_ok_and(|target| &target == package) {
            continue;
        }
        std::fs::create_dir_all(dir)?;
        let tmp = dir.join(format!(
            ".{}-{}.link",
            file_name.to_string_lossy(),
            std::process::id()
        ));
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(package, &tmp)?;
        std::fs::rename(&tmp, &link)?;
    }
    Ok(())
}
