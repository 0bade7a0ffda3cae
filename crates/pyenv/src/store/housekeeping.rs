//! Housekeeping: the stored environments listed with the disk they use and when they were
//! last used, removed by name, and pruned by rule (unused for a while, no longer declared,
//! over a disk budget). Never an environment that running workers hold (their shared
//! `flock` on its manifest, see [`PythonEnv::hold`](super::PythonEnv::hold)), nor one being
//! built (its build lock).

use super::{INSTALLS, LAST_USE, MANIFEST, Manifest, Store, read_manifest};
use crate::error::{PyEnvError, io};
use crate::{hold, lock};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// Which stored environments [`Store::prune`] removes: any that one of the rules selects.
#[derive(Clone, Debug, Default)]
pub struct PruneRule {
    /// Those unused (no session, no build) for this long.
    pub unused_for: Option<Duration>,
    /// Those whose folder is not one of these (the folders the registries' environments
    /// resolve to); `None`: not this rule.
    pub named: Option<Vec<PathBuf>>,
    /// Then the least recently used, until the cache uses at most this much disk.
    pub max_bytes: Option<u64>,
}

/// What [`Store::prune`] did.
#[derive(Clone, Debug, Default)]
pub struct Pruned {
    /// The folders removed (or to remove), with the disk each used.
    pub removed: Vec<(PathBuf, u64)>,
    /// The folders kept because running workers hold them, with their pids.
    pub in_use: Vec<(PathBuf, Vec<u32>)>,
    /// Disk the environments left use together.
    pub left_bytes: u64,
}

/// An environment found in the cache folder.
#[derive(Clone, Debug)]
pub struct Stored {
    /// Its folder's name (`metaworld-2b38c1c44ecc8a00`).
    pub dir_name: String,
    /// Its folder.
    pub dir: PathBuf,
    /// Its manifest, when it is ready.
    pub manifest: Option<Manifest>,
    /// Disk it uses: allocated blocks, each hard-linked file once (most are links into uv's
    /// cache, which they share with it and with other venvs).
    pub size_bytes: u64,
    /// When a hub last used it (or it was built).
    pub last_use: Option<SystemTime>,
}

impl Store {
    /// Every environment folder in the cache, ready or not, by name.
    pub fn list(&self) -> Vec<Stored> {
        let Ok(read) = std::fs::read_dir(&self.root) else {
            return Vec::new();
        };
        let mut found: Vec<Stored> = read
            .flatten()
            .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
            .filter(|e| e.file_name() != INSTALLS)
            .map(|e| {
                let dir = e.path();
                Stored {
                    dir_name: e.file_name().to_string_lossy().into_owned(),
                    manifest: read_manifest(&dir),
                    size_bytes: disk_usage(&dir, &mut HashSet::new()),
                    last_use: std::fs::metadata(dir.join(LAST_USE))
                        .and_then(|m| m.modified())
                        .ok(),
                    dir,
                }
            })
            .collect();
        found.sort_by(|a, b| a.dir_name.cmp(&b.dir_name));
        found
    }

    /// Removes every stored folder of the environment `name` (or the one folder named
    /// `name`), builds in progress excepted; returns the folders removed. A folder that
    /// running workers hold (see [`PythonEnv::hold`]) is refused with their pids, unless
    /// `force`: then they lose it under them (a restart says it was removed).
    pub fn remove(&self, name: &str, force: bool) -> Result<Vec<PathBuf>, PyEnvError> {
        let stored = self.list();
        let matching: Vec<&Stored> = stored
            .iter()
            .filter(|s| {
                s.dir_name == name
                    || s.manifest.as_ref().is_some_and(|m| m.name == name)
                    || (s.dir_name.starts_with(".tmp-")
                        && s.dir_name[5..].starts_with(&format!("{name}-")))
            })
            .collect();
        if matching.is_empty() {
            let mut known: Vec<String> = stored
                .iter()
                .filter_map(|s| s.manifest.as_ref().map(|m| m.name.clone()))
                .collect();
            known.dedup();
            return Err(PyEnvError::NotStored {
                name: name.to_string(),
                root: self.root.clone(),
                known,
            });
        }
        if !force {
            for s in &matching {
                if let Some(pids) = self.held(s)? {
                    return Err(in_use(name, &s.dir, &pids));
                }
            }
        }
        let mut removed = Vec::new();
        for s in matching {
            // Not while it is being built: its builder holds the lock (`<name>-<key>.lock`).
            let stem = match &s.manifest {
                Some(m) => format!("{}-{}", m.name, m.key),
                None => {
                    let rest = s.dir_name.trim_start_matches(".tmp-");
                    rest.rsplitn(3, '-').nth(2).unwrap_or(rest).to_string()
                }
            };
            let lock_path = self.root.join(format!("{stem}.lock"));
            let _lock = lock::acquire(name, &lock_path, Duration::ZERO, |_| {})?;
            // Held while it goes: a worker starting meanwhile waits, then finds it gone.
            let _hold = match hold::exclusive(&s.dir.join(MANIFEST)) {
                Ok(Some(Ok(hold))) => Some(hold),
                Ok(Some(Err(pids))) if !force => return Err(in_use(name, &s.dir, &pids)),
                _ => None,
            };
            self.remove_dir(name, s)?;
            removed.push(s.dir.clone());
        }
        Ok(removed)
    }

    /// The pids of the running workers that hold `stored` (`Some(empty)`: held by processes
    /// that cannot be told), or `None` when none does.
    fn held(&self, stored: &Stored) -> Result<Option<Vec<u32>>, PyEnvError> {
        let path = stored.dir.join(MANIFEST);
        match hold::exclusive(&path) {
            Ok(Some(Err(pids))) => Ok(Some(pids)),
            Ok(_) => Ok(None),
            Err(e) => Err(io(&stored.dir_name, "open", &path)(e)),
        }
    }

    /// Removes the folder of `s`: renamed aside first, so that no one finds it half gone.
    fn remove_dir(&self, name: &str, s: &Stored) -> Result<(), PyEnvError> {
        let trash = self.root.join(format!(
            ".trash-{}-{}",
            s.dir_name.trim_start_matches('.'),
            std::process::id()
        ));
        std::fs::rename(&s.dir, &trash).map_err(io(name, "remove", &s.dir))?;
        std::fs::remove_dir_all(&trash).map_err(io(name, "remove", &trash))
    }

    /// Removes, of the stored environments, those `rule` selects — never one that running
    /// workers hold — and says what it removed or would remove (`dry_run`).
    pub fn prune(&self, rule: &PruneRule, dry_run: bool) -> Result<Pruned, PyEnvError> {
        let stored: Vec<Stored> = self
            .list()
            .into_iter()
            .filter(|s| !s.dir_name.starts_with('.'))
            .collect();
        let now = SystemTime::now();
        let mut pruned = Pruned::default();
        let mut left: Vec<&Stored> = Vec::new();
        for s in &stored {
            if let Some(pids) = self.held(s)? {
                pruned.in_use.push((s.dir.clone(), pids));
                continue;
            }
            let unused = rule.unused_for.is_some_and(|limit| {
                s.last_use
                    .and_then(|t| now.duration_since(t).ok())
                    .is_none_or(|age| age >= limit)
            });
            let unnamed = rule
                .named
                .as_ref()
                .is_some_and(|named| !named.contains(&s.dir));
            if unused || unnamed {
                pruned.removed.push((s.dir.clone(), s.size_bytes));
            } else {
                left.push(s);
            }
        }
        if let Some(budget) = rule.max_bytes {
            // The least recently used go first, until what is left fits.
            left.sort_by_key(|s| s.last_use);
            let kept_in_use: Vec<PathBuf> = pruned.in_use.iter().map(|(d, _)| d.clone()).collect();
            while disk_usage_of(
                left.iter()
                    .map(|s| s.dir.as_path())
                    .chain(kept_in_use.iter().map(PathBuf::as_path)),
            ) > budget
                && !left.is_empty()
            {
                let s = left.remove(0);
                pruned.removed.push((s.dir.clone(), s.size_bytes));
            }
        }
        if !dry_run {
            for (dir, _) in &pruned.removed {
                let s = stored.iter().find(|s| &s.dir == dir).expect("listed");
                let name = s
                    .manifest
                    .as_ref()
                    .map_or(s.dir_name.as_str(), |m| m.name.as_str());
                let _hold = match hold::exclusive(&dir.join(MANIFEST)) {
                    Ok(Some(Err(pids))) => return Err(in_use(name, dir, &pids)),
                    Ok(Some(Ok(hold))) => Some(hold),
                    _ => None,
                };
                self.remove_dir(name, s)?;
            }
        }
        pruned.left_bytes = disk_usage_of(
            stored
                .iter()
                .filter(|s| !pruned.removed.iter().any(|(d, _)| d == &s.dir))
                .map(|s| s.dir.as_path()),
        );
        Ok(pruned)
    }
}

/// Disk used by the files under `dir`: allocated blocks, each file once however many hard
/// links lead to it (`seen`: the files already counted, by device and inode).
fn disk_usage(dir: &Path, seen: &mut HashSet<(u64, u64)>) -> u64 {
    use std::os::unix::fs::MetadataExt;
    let Ok(read) = std::fs::read_dir(dir) else {
        return 0;
    };
    read.flatten()
        .map(|e| match e.metadata() {
            Ok(m) if m.is_dir() => disk_usage(&e.path(), seen),
            Ok(m) if seen.insert((m.dev(), m.ino())) => m.blocks() * 512,
            _ => 0,
        })
        .sum()
}

/// Disk used by all of `dirs` together (a file linked into several counted once).
fn disk_usage_of<'a>(dirs: impl Iterator<Item = &'a Path>) -> u64 {
    let mut seen = HashSet::new();
    dirs.map(|d| disk_usage(d, &mut seen)).sum()
}

/// The error for a folder that running workers (`pids`) hold.
fn in_use(name: &str, dir: &Path, pids: &[u32]) -> PyEnvError {
    PyEnvError::InUse {
        name: name.to_string(),
        dir: dir.to_path_buf(),
        pids: if pids.is_empty() {
            "pids unknown".into()
        } else {
            let list: Vec<String> = pids.iter().map(u32::to_string).collect();
            format!("pid {}", list.join(", "))
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disk_usage_counts_a_hard_linked_file_once() {
        let dir = std::env::temp_dir().join(format!("envhub-du-test-{}", std::process::id()));
        let (a, b) = (dir.join("a"), dir.join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        std::fs::write(a.join("data"), vec![1u8; 1 << 20]).unwrap();
        std::fs::hard_link(a.join("data"), a.join("again")).unwrap();
        std::fs::hard_link(a.join("data"), b.join("data")).unwrap();
        let one = disk_usage(&a, &mut HashSet::new());
        assert!((1 << 20..(1 << 20) + 65_536).contains(&one), "{one}");
        assert_eq!(disk_usage_of([a.as_path(), b.as_path()].into_iter()), one);
        assert_eq!(disk_usage(&b, &mut HashSet::new()), one);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
