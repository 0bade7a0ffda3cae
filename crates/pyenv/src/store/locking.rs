//! Locking: resolving a declaration with uv's resolver (`uv pip compile`) for each target
//! platform into its lock entry, in a private scratch folder. Apart from building because
//! it installs nothing and needs no interpreter of the declared version.

use super::Store;
use crate::error::{PyEnvError, io};
use crate::uv;
use envhub_catalog::{EnvLock, PythonEnvSpec, package_name};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

impl Store {
    /// Resolves `spec` with uv's resolver (`uv pip compile`) for each of `platforms` (uv's
    /// target names): its lock entry. Needs no interpreter of its version on this machine
    /// unless an sdist must be built to learn its dependencies.
    pub fn lock(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
        platforms: &[String],
    ) -> Result<EnvLock, PyEnvError> {
        spec.validate().map_err(|message| PyEnvError::InvalidSpec {
            name: name.to_string(),
            message,
        })?;
        let version = match &spec.python {
            Some(requested) => requested.trim().to_string(),
            None => self.base_and_version(name, spec)?.1,
        };
        let requirements = spec.full_requirements(&self.extra_requirements);
        let no_deps = spec.no_deps_sorted();
        // Outside the cache folder, where `list` and `prune` would take it for a build; a
        // fresh folder of a random name in this user's private folder, which no one else
        // can have made first or enter.
        let private = envhub_core::private_dir::runtime_dir("scratch")
            .map_err(std::io::Error::other)
            .map_err(io(
                name,
                "make a private folder for",
                Path::new("lock scratch"),
            ))?;
        let scratch = envhub_core::private_dir::fresh_dir(&private, &format!("lock-{name}-"))
            .map_err(io(name, "create a scratch folder in", &private))?;
        let result = (|| {
            let mut locked = EnvLock {
                declaration: spec.declaration_hash(&self.extra_requirements),
                python: version.clone(),
                platforms: BTreeMap::new(),
            };
            for platform in platforms {
                let mut pins = self.compile(
                    name,
                    spec,
                    &scratch,
                    &version,
                    platform,
                    &requirements,
                    false,
                )?;
                if !no_deps.is_empty() {
                    let bare =
                        self.compile(name, spec, &scratch, &version, platform, &no_deps, true)?;
                    // Installed after the others, so their version wins.
                    let names: Vec<String> = bare.iter().map(|p| package_name(p)).collect();
                    pins.retain(|p| !names.contains(&package_name(p)));
                    pins.extend(bare);
                }
                pins.sort();
                pins.dedup();
                locked.platforms.insert(platform.clone(), pins);
            }
            Ok(locked)
        })();
        let _ = std::fs::remove_dir_all(&scratch);
        result
    }

    /// One `uv pip compile` of `requirements` for `platform`: `name==version` pins.
    #[allow(clippy::too_many_arguments)]
    fn compile(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
        scratch: &Path,
        version: &str,
        platform: &str,
        requirements: &[String],
        no_deps: bool,
    ) -> Result<Vec<String>, PyEnvError> {
        let tag = if no_deps { "no-deps" } else { "requirements" };
        let input = scratch.join(format!("{tag}.in"));
        let output = scratch.join(format!("{tag}-{platform}.txt"));
        let text: String = requirements.iter().map(|r| format!("{r}\n")).collect();
        std::fs::write(&input, text).map_err(io(name, "write", &input))?;
        let mut compile = Command::new(&self.uv);
        compile
            .args(["pip", "compile", "--quiet", "--no-header", "--no-annotate"])
            .args(["--python-version", version, "--python-platform", platform])
            .args(spec.uv_args());
        if no_deps {
            compile.arg("--no-deps");
        }
        compile.arg(&input).arg("-o").arg(&output);
        let show = self.progress;
        uv::run(compile, Duration::from_secs(10), |elapsed| {
            if show {
                eprintln!(
                    "envhub: python env `{name}`: resolving for {platform} ({} s)",
                    elapsed.as_secs()
                );
            }
        })
        .map_err(|uv::Failed(message)| PyEnvError::Install {
            name: name.to_string(),
            stage: format!("`uv pip compile` for {platform}, Python {version}"),
            packages: uv::named_packages(&message, requirements),
            message,
        })?;
        let text = std::fs::read_to_string(&output).map_err(io(name, "read", &output))?;
        Ok(pins_of(&text))
    }
}

/// The `name==version` lines of a `uv pip compile` output (comments, options and blank
/// lines dropped).
fn pins_of(text: &str) -> Vec<String> {
    let mut pins: Vec<String> = text
        .lines()
        .map(|l| l.split(" #").next().unwrap_or("").trim())
        .filter(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with('-'))
        .map(String::from)
        .collect();
    pins.sort();
    pins
}

/// A pin with its package name normalized (`PyOpenGL==3.1.10` → `pyopengl==3.1.10`).
pub(super) fn normal_pin(pin: &str) -> String {
    match pin.split_once("==") {
        Some((name, version)) => format!("{}=={}", package_name(name), version.trim()),
        None => pin.trim().to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compile_output_becomes_pins() {
        let text = "# header\nmujoco==3.3.0\n    # via metaworld\n--index-url https://x\n\nabsl-py==2.5.1  # comment\n";
        assert_eq!(pins_of(text), ["absl-py==2.5.1", "mujoco==3.3.0"]);
        assert_eq!(normal_pin("PyOpenGL==3.1.10"), "pyopengl==3.1.10");
    }
}
