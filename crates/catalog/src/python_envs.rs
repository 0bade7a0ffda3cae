//! The registry's Python environments: `python_envs:` (name → requirements) and
//! `frameworks:` (a framework's default environment), and which one an entry runs in.
//!
//! ```yaml
//! python_envs:
//!   metaworld: {python: "3.11", requirements: ["metaworld==3.1.1"], env: {MUJOCO_GL: egl}}
//! frameworks:
//!   metaworld: {python_env: metaworld}
//! environments:
//!   - {id: metaworld-reach, framework: metaworld, env_id: Meta-World/MT1, python_env: metaworld, ...}
//! ```
//!
//! An entry's own `python_env:` wins over its framework's. Building them is
//! the provisioning's part (`envhub-pyenv`, driven by the facade).

use crate::entry::EnvEntry;
use crate::env_lock::{LockFile, Locking};
use crate::python_env_spec::PythonEnvSpec;
use crate::registry_error::{RegistryError, id_lines};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A framework's settings in a registry file (`frameworks:`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameworkDefaults {
    /// The Python environment its entries run in, unless an entry names its own.
    #[serde(default)]
    pub python_env: Option<String>,
}

/// The Python environments of a registry, combined over its files (a later file's definition
/// of a name replaces an earlier one).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PythonEnvs {
    specs: BTreeMap<String, PythonEnvSpec>,
    frameworks: BTreeMap<String, String>,
    lock_files: BTreeMap<String, Option<PathBuf>>,
}

/// A registry file's lock file, as loading found it.
#[derive(Clone, Debug, Default)]
pub struct LockSource {
    /// Where it is, or would be written (`None`: nowhere writable, such as the built-in
    /// catalog outside an envhub checkout).
    pub path: Option<PathBuf>,
    /// Its content, where it exists.
    pub file: Option<LockFile>,
    /// Its name in messages.
    pub name: String,
}

impl PythonEnvs {
    /// The environment named `name`.
    pub fn get(&self, name: &str) -> Option<&PythonEnvSpec> {
        self.specs.get(name)
    }

    /// Every environment, by name.
    pub fn all(&self) -> &BTreeMap<String, PythonEnvSpec> {
        &self.specs
    }

    /// Where the lock file of the registry file declaring `name` is, or would be written.
    pub fn lock_file(&self, name: &str) -> Option<&Path> {
        self.lock_files.get(name)?.as_deref()
    }

    /// The name of the environment `entry` runs in: its own `python_env`, else its
    /// framework's.
    pub fn name_for<'a>(&'a self, entry: &'a EnvEntry) -> Option<&'a str> {
        entry.python_env.as_deref().or_else(|| {
            self.frameworks
                .get(&framework_key(&entry.framework))
                .map(String::as_str)
        })
    }

    /// Merges one file's `python_envs:` and `frameworks:`, and checks that every name its
    /// entries and frameworks use is defined (in this file or an earlier one).
    pub(crate) fn add_file(
        &mut self,
        specs: BTreeMap<String, PythonEnvSpec>,
        frameworks: BTreeMap<String, FrameworkDefaults>,
        entries: &[EnvEntry],
        text: &str,
        path: &str,
        lock: &LockSource,
    ) -> Result<(), RegistryError> {
        let mut specs = specs;
        for (name, spec) in &specs {
            let message = if !crate::python_env_spec::valid_name(name) {
                Some(format!(
                    "`{name}` is not a valid name; use letters, digits, `-`, `_` and `.`"
                ))
            } else {
                spec.validate().err()
            };
            if let Some(message) = message {
                return Err(RegistryError::PythonEnv {
                    path: path.to_string(),
                    line: line_of(text, &format!("{name}:")),
                    message: format!("`python_envs.{name}`: {message}"),
                });
            }
        }
        for (name, spec) in specs.iter_mut() {
            spec.lock = match &lock.file {
                None => Locking::Unlocked,
                Some(file) => match file.python_envs.get(name) {
                    Some(entry) => Locking::Locked {
                        file: lock.name.clone(),
                        lock: entry.clone(),
                    },
                    None => Locking::Missing {
                        file: lock.name.clone(),
                    },
                },
            };
            self.lock_files.insert(name.clone(), lock.path.clone());
        }
        self.specs.extend(specs);
        let unknown = |used: &str, by: String, line: usize| RegistryError::PythonEnv {
            path: path.to_string(),
            line,
            message: format!(
                "{by} names the python env `{used}`, which is not defined{}\nhint: define it under `python_envs:` (in this file or an earlier registry file), or fix the name",
                known(&self.specs)
            ),
        };
        for (framework, defaults) in frameworks {
            if let Some(name) = defaults.python_env {
                if !self.specs.contains_key(&name) {
                    let line = line_of(text, &format!("{framework}:"));
                    return Err(unknown(&name, format!("`frameworks.{framework}`"), line));
                }
                self.frameworks.insert(framework_key(&framework), name);
            }
        }
        for entry in entries {
            if let Some(name) = &entry.python_env
                && !self.specs.contains_key(name)
            {
                let line = id_lines(text, &entry.id).first().copied().unwrap_or(0);
                return Err(unknown(name, format!("entry `{}`", entry.id), line));
            }
        }
        Ok(())
    }
}

/// Frameworks are matched by canonical name (`isaaclab` and `isaac_lab` are one).
fn framework_key(framework: &str) -> String {
    envhub_core::canonical_framework(framework)
        .map(str::to_string)
        .unwrap_or_else(|| framework.trim().to_lowercase())
}

fn known(specs: &BTreeMap<String, PythonEnvSpec>) -> String {
    if specs.is_empty() {
        " (none is defined)".into()
    } else {
        let names: Vec<String> = specs.keys().map(|k| format!("`{k}`")).collect();
        format!(" (defined: {})", names.join(", "))
    }
}

/// 1-based line of the first line that starts (after indentation) with `prefix`; 0 if none.
fn line_of(text: &str, prefix: &str) -> usize {
    text.lines()
        .position(|l| l.trim_start().starts_with(prefix))
        .map_or(0, |i| i + 1)
}

#[cfg(test)]
mod tests {
    use crate::registry::Registry;
    use std::path::Path;

    const FILE: &str = r#"
python_envs:
  tiny:
    python: "3.11"
    requirements: ["packaging==24.2"]
    env: {MUJOCO_GL: egl}
frameworks:
  metaworld: {python_env: tiny}
environments:
  - {id: a, name: A, framework: metaworld, env_id: X-v0, robot_type: arm, env_type: tabletop}
  - id: b
    name: B
    framework: gymnasium
    env_id: Y-v0
    robot_type: arm
    env_type: tabletop
    python_env: tiny
  - {id: c, name: C, framework: gymnasium, env_id: Z-v0, robot_type: arm, env_type: tabletop}
"#;

    fn load(text: &str) -> Result<Registry, String> {
        let mut r = Registry::default();
        r.add_yaml(text, "suites.yaml", Path::new("."))
            .map_err(|e| e.to_string())?;
        Ok(r)
    }

    #[test]
    fn entries_run_in_their_own_or_their_frameworks_env() {
        let r = load(FILE).unwrap();
        let envs = r.python_envs();
        let of = |id: &str| envs.name_for(r.get(id).unwrap()).map(str::to_string);
        assert_eq!(of("a").as_deref(), Some("tiny"));
        assert_eq!(of("b").as_deref(), Some("tiny"));
        assert_eq!(of("c"), None);
        assert_eq!(envs.get("tiny").unwrap().env["MUJOCO_GL"], "egl");
    }

    #[test]
    fn an_unknown_name_is_an_error_with_line_and_the_known_names() {
        let text = FILE.replace("    python_env: tiny\n", "    python_env: tinny\n");
        let err = load(&text).unwrap_err();
        assert!(
            err.starts_with("suites.yaml:11: entry `b` names the python env `tinny`")
                && err.contains("(defined: `tiny`)")
                && err.contains("hint:"),
            "{err}"
        );
        let text = FILE.replace(
            "metaworld: {python_env: tiny}",
            "metaworld: {python_env: nope}",
        );
        let err = load(&text).unwrap_err();
        assert!(
            err.starts_with("suites.yaml:8: `frameworks.metaworld` names"),
            "{err}"
        );
        let text = FILE.replace("requirements: [\"packaging==24.2\"]", "requirements: []");
        let err = load(&text).unwrap_err();
        assert!(
            err.starts_with("suites.yaml:3: `python_envs.tiny`: `requirements` is empty"),
            "{err}"
        );
        let text = FILE.replace("    env: {MUJOCO_GL: egl}", "    envs: {MUJOCO_GL: egl}");
        let err = load(&text).unwrap_err();
        assert!(err.contains("unknown field `envs`"), "{err}");
    }

    #[test]
    fn a_later_file_may_use_an_earlier_files_env() {
        let mut r = Registry::default();
        r.add_yaml(FILE, "first.yaml", Path::new(".")).unwrap();
        let later = "environments:\n  - {id: d, name: D, framework: gymnasium, env_id: W-v0, robot_type: arm, env_type: floor, python_env: tiny}\n";
        r.add_yaml(later, "second.yaml", Path::new(".")).unwrap();
        assert_eq!(r.python_envs().name_for(r.get("d").unwrap()), Some("tiny"));
    }
}
