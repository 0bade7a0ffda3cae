//! Planning: what an environment's declaration resolves to before anything is built — its
//! key (a hash of the interpreter version, the requirements, the platform and the lock's
//! pins), its folder and the interpreter to base it on — and how a declaration stands
//! against its lock. Apart from building so that `envhub env list` and `lock` can ask
//! without installing anything.

use super::{Plan, Store, last_lines};
use crate::error::PyEnvError;
use crate::interpreter::{self, Interpreter};
use crate::uv;
use envhub_catalog::{Locking, PythonEnvSpec, parse_version, valid_name};
use std::path::PathBuf;

impl Store {
    /// Resolves `spec` to its key, folder and base interpreter, without building anything.
    pub fn plan(&self, name: &str, spec: &PythonEnvSpec) -> Result<Plan, PyEnvError> {
        let invalid = |message: String| PyEnvError::InvalidSpec {
            name: name.to_string(),
            message,
        };
        if !valid_name(name) {
            return Err(invalid(format!(
                "`{name}` is not a valid name; use letters, digits, `-`, `_` and `.`"
            )));
        }
        spec.validate().map_err(invalid)?;
        let (base, version) = self.base_and_version(name, spec)?;
        let platform = uv::platform();
        let locked = self.locked_pins(name, spec, &version, &platform)?;
        let mut context = format!("platform {platform}\n");
        for pin in locked.iter().flatten() {
            context.push_str(&format!("locked {pin}\n"));
        }
        context.push_str(&uv::settings());
        let key = spec.key(&version, &self.extra_requirements, &context);
        Ok(Plan {
            name: name.to_string(),
            dir: self.root.join(format!("{name}-{key}")),
            key,
            base,
            requirements: spec.full_requirements(&self.extra_requirements),
            no_deps: spec.no_deps_sorted(),
            env: spec.env.clone(),
            platform,
            locked,
            uv_args: spec.uv_args(),
        })
    }

    /// The pins of `spec`'s lock for `platform`; `None` where its registry has no lock
    /// file; an error naming the fix where the lock does not fit the declaration.
    fn locked_pins(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
        version: &str,
        platform: &str,
    ) -> Result<Option<Vec<String>>, PyEnvError> {
        let refused = |message: String| PyEnvError::Lock {
            name: name.to_string(),
            message,
        };
        let (file, lock) = match &spec.lock {
            Locking::Unlocked => return Ok(None),
            Locking::Missing { file } => {
                return Err(refused(format!(
                    "is not in the lock file `{file}`: it was added to the registry without relocking\nhint: `envhub env lock {name}` resolves it (then commit the lock file)"
                )));
            }
            Locking::Locked { file, lock } => (file, lock),
        };
        let declared = spec.declaration_hash(&self.extra_requirements);
        if lock.declaration != declared {
            return Err(refused(format!(
                "its declaration in the registry changed since it was locked (the lock file `{file}` was made from declaration {}, the registry's is {declared})\nhint: `envhub env lock {name}` resolves it again (then commit the lock file)",
                lock.declaration
            )));
        }
        if lock.python != version {
            return Err(refused(format!(
                "the lock file `{file}` is for Python {}, but it would be built on Python {version} (the hub's interpreter's version, as it names none)\nhint: name `python: \"{}\"` in its declaration, or `envhub env lock {name}` with this interpreter",
                lock.python, lock.python
            )));
        }
        match lock.platforms.get(platform) {
            Some(pins) => Ok(Some(pins.clone())),
            None => Err(refused(format!(
                "the lock file `{file}` has no pins for this platform, {platform} (it has {})\nhint: `envhub env lock {name} --platform {platform}` adds them (then commit the lock file)",
                if lock.platforms.is_empty() {
                    "none".to_string()
                } else {
                    lock.platforms
                        .keys()
                        .cloned()
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ))),
        }
    }

    /// The interpreter to base `spec` on and its version as the key names it (as the
    /// registry writes it, else the hub's interpreter's major.minor).
    pub(super) fn base_and_version(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
    ) -> Result<(PathBuf, String), PyEnvError> {
        let invalid = |message: String| PyEnvError::InvalidSpec {
            name: name.to_string(),
            message,
        };
        Ok(match &spec.python {
            Some(requested) => {
                let path = self.find_python(name, requested)?;
                (path, requested.trim().to_string())
            }
            None => {
                let version = self
                    .default_version
                    .get_or_init(|| interpreter::version_of(&self.default_python))
                    .clone()
                    .ok_or_else(|| {
                        invalid(format!(
                            "cannot run the hub's interpreter `{}` to learn its version; name one with `python:`",
                            self.default_python.display()
                        ))
                    })?;
                let (major, minor, _) = parse_version(&version).expect("checked by version_of");
                (self.default_python.clone(), format!("{major}.{minor}"))
            }
        })
    }

    /// How `spec` stands against its lock, in a word or three for `envhub env list`:
    /// `unlocked`, `locked`, `stale` (declaration changed), `not in lock`,
    /// `no pins for <platform>`, `locked for Python <version>`.
    pub fn lock_state(&self, name: &str, spec: &PythonEnvSpec) -> String {
        let lock = match &spec.lock {
            Locking::Unlocked => return "unlocked".into(),
            Locking::Missing { .. } => return "not in lock".into(),
            Locking::Locked { lock, .. } => lock,
        };
        if lock.declaration != spec.declaration_hash(&self.extra_requirements) {
            return "stale".into();
        }
        let version = match &spec.python {
            Some(v) => v.trim().to_string(),
            None => match self.base_and_version(name, spec) {
                Ok((_, v)) => v,
                Err(_) => lock.python.clone(),
            },
        };
        let platform = uv::platform();
        if lock.python != version {
            format!("locked for Python {}", lock.python)
        } else if !lock.platforms.contains_key(&platform) {
            format!("no pins for {platform}")
        } else {
            "locked".into()
        }
    }

    /// The newest CPython (default build) matching `requested`: pyenv's, then those uv
    /// finds, each asked what it is; else, where allowed, one uv installs.
    fn find_python(&self, name: &str, requested: &str) -> Result<PathBuf, PyEnvError> {
        let matching = |list: &[Interpreter]| {
            let mut found: Vec<Interpreter> = list
                .iter()
                .filter(|i| version_matches(&i.version, requested))
                .cloned()
                .collect();
            found.sort_by_key(|i| std::cmp::Reverse(parse_version(&i.version)));
            found.into_iter().find(|i| self.qualifies(i))
        };
        if let Some(found) =
            matching(self.pyenv_interpreters()).or_else(|| matching(self.uv_interpreters()))
        {
            return Ok(found.path);
        }
        let not_found = |tried: String| PyEnvError::PythonNotFound {
            name: name.to_string(),
            requested: requested.trim().to_string(),
            present: interpreter::describe(self.interpreters()),
            tried,
        };
        if !self.python_install {
            return Err(not_found(String::new()));
        }
        if self.progress {
            eprintln!("envhub: python env `{name}`: asking uv to install CPython {requested}");
        }
        match interpreter::install_with_uv(&self.uv, requested.trim()) {
            Ok(path)
                if interpreter::version_of(&path).is_some_and(|v| {
                    version_matches(&v, requested) && interpreter::qualifies(&path, &v)
                }) =>
            {
                Ok(path)
            }
            Ok(path) => Err(not_found(format!(
                "; uv installed `{}`, which is not a CPython {requested} of the default build",
                path.display()
            ))),
            Err(message) => Err(not_found(format!(
                "; `uv python install {requested}` failed: {}",
                last_lines(&message, 4)
            ))),
        }
    }

    /// Whether `i` is what it says and envhub can use it (asked once per interpreter).
    fn qualifies(&self, i: &Interpreter) -> bool {
        let mut known = self.qualified.lock().unwrap_or_else(|e| e.into_inner());
        *known
            .entry(i.path.clone())
            .or_insert_with(|| interpreter::qualifies(&i.path, &i.version))
    }
}

/// Whether an interpreter's `version` is the `requested` one (`3.10` or `3.10.13`).
fn version_matches(version: &str, requested: &str) -> bool {
    match (parse_version(version), parse_version(requested)) {
        (Some((a, b, c)), Some((x, y, z))) => (a, b) == (x, y) && (z.is_none() || c == z),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use envhub_catalog::EnvLock;
    use std::collections::BTreeMap;

    #[test]
    fn the_lock_state_says_how_a_declaration_fits_its_lock() {
        let store = Store::new("/nonexistent".into(), "uv".into(), "python3".into())
            .with_extra_requirements(vec!["numpy".into()]);
        let mut spec = PythonEnvSpec {
            python: Some("3.11".into()),
            requirements: vec!["mujoco==3.3.0".into()],
            ..Default::default()
        };
        assert_eq!(store.lock_state("s", &spec), "unlocked");
        let mut lock = EnvLock {
            declaration: spec.declaration_hash(&["numpy".into()]),
            python: "3.11".into(),
            platforms: BTreeMap::new(),
        };
        lock.platforms
            .insert(uv::platform(), vec!["mujoco==3.3.0".into()]);
        let locked = |lock: &EnvLock| Locking::Locked {
            file: "s.lock.yaml".into(),
            lock: lock.clone(),
        };
        spec.lock = locked(&lock);
        assert_eq!(store.lock_state("s", &spec), "locked");
        // The worker's requirements are part of what was locked.
        let bare = Store::new("/nonexistent".into(), "uv".into(), "python3".into());
        assert_eq!(bare.lock_state("s", &spec), "stale");
        let mut other = lock.clone();
        other.platforms = [("riscv64-unknown-linux".to_string(), vec![])].into();
        spec.lock = locked(&other);
        assert_eq!(
            store.lock_state("s", &spec),
            format!("no pins for {}", uv::platform())
        );
        let mut older = lock.clone();
        older.python = "3.10".into();
        spec.lock = locked(&older);
        assert_eq!(store.lock_state("s", &spec), "locked for Python 3.10");
        spec.lock = Locking::Missing {
            file: "s.lock.yaml".into(),
        };
        assert_eq!(store.lock_state("s", &spec), "not in lock");
        spec.lock = locked(&lock);
        spec.requirements.push("packaging".into());
        assert_eq!(store.lock_state("s", &spec), "stale");
    }
}
