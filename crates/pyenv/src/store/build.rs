//! Building: a venv made with uv in a temporary folder (`.tmp-<name>-<key>-*`), its
//! packages installed (exactly the lock's, or resolved), envhub's package imported through
//! the overlay as a check, what it resolved to written into its manifest, and only then
//! renamed into place — so nothing half-installed is ever found ready. Called by
//! [`Store::ensure`] under the environment's build lock.

use super::locking::normal_pin;
use super::{MANIFEST, Manifest, Plan, PythonEnv, Store, last_lines};
use crate::error::{PyEnvError, io};
use crate::interpreter;
use crate::uv;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

impl Store {
    /// Clears what an interrupted build of `plan` left (its temporary folders, trash) and a
    /// folder of the same key that is not ready, before it is built again.
    pub(super) fn clear_leftovers(&self, plan: &Plan) -> Result<(), PyEnvError> {
        let prefix = format!(".tmp-{}-{}-", plan.name, plan.key);
        for entry in std::fs::read_dir(&self.root)
            .map_err(io(&plan.name, "read", &self.root))?
            .flatten()
        {
            let file_name = entry.file_name();
            let file_name = file_name.to_string_lossy();
            if file_name.starts_with(&prefix) || file_name.starts_with(".trash-") {
                tracing::info!(folder = %file_name, "removing an interrupted build");
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        if plan.dir.exists() {
            // Built for other requirements under the same key, or damaged: rebuilt.
            std::fs::remove_dir_all(&plan.dir).map_err(io(&plan.name, "remove", &plan.dir))?;
        }
        Ok(())
    }

    /// Builds `plan` in a temporary folder and renames it into place.
    pub(super) fn build(&self, plan: &Plan) -> Result<PythonEnv, PyEnvError> {
        let name = &plan.name;
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
            .subsec_nanos();
        let tmp = self.root.join(format!(
            ".tmp-{name}-{}-{}-{nanos}",
            plan.key,
            std::process::id()
        ));
        let start = Instant::now();
        if self.progress {
            eprintln!(
                "envhub: building python env `{name}` ({} requirements, on `{}`) into `{}`; this can take minutes",
                plan.requirements.len(),
                plan.base.display(),
                plan.dir.display()
            );
        }
        let result = self.build_in(plan, &tmp, start);
        if result.is_err() {
            let _ = std::fs::remove_dir_all(&tmp);
        }
        result?;
        std::fs::rename(&tmp, &plan.dir).map_err(io(name, "rename into place", &tmp))?;
        if self.progress {
            eprintln!(
                "envhub: python env `{name}` ready in {:.1} s",
                start.elapsed().as_secs_f64()
            );
        }
        Ok(PythonEnv {
            name: name.clone(),
            key: plan.key.clone(),
            python: plan.dir.join("bin").join("python"),
            dir: plan.dir.clone(),
            env: plan.env.clone(),
            built: true,
        })
    }

    fn build_in(&self, plan: &Plan, tmp: &Path, start: Instant) -> Result<(), PyEnvError> {
        let name = &plan.name;
        let failed = |stage: &str, message: String| PyEnvError::Install {
            name: name.clone(),
            stage: stage.to_string(),
            packages: uv::named_packages(&message, &plan.requirements),
            message,
        };
        let every = Duration::from_secs(10);
        let progress = |stage: &'static str| {
            let show = self.progress;
            move |elapsed: Duration| {
                if show {
                    eprintln!(
                        "envhub: python env `{name}`: {stage} ({} s)",
                        elapsed.as_secs()
                    );
                }
            }
        };
        let mut venv = Command::new(&self.uv);
        venv.args([
            "venv",
            "--quiet",
            "--relocatable",
            "--no-python-downloads",
            "--python",
        ])
        .arg(&plan.base)
        .arg(tmp);
        uv::run(venv, every, progress("creating the venv")).map_err(|uv::Failed(m)| {
            PyEnvError::Install {
                name: name.clone(),
                stage: "`uv venv`".into(),
                packages: format!("its interpreter `{}`", plan.base.display()),
                message: m,
            }
        })?;
        let python = tmp.join("bin").join("python");
        if let Some(pins) = &plan.locked {
            // Exactly the lock: `uv pip sync` installs what it lists and nothing else (no
            // resolution, no dependency it does not list), and removes anything else.
            let file = tmp.join("envhub-lock.txt");
            let text: String = pins.iter().map(|p| format!("{p}\n")).collect();
            std::fs::write(&file, text).map_err(io(name, "write", &file))?;
            let mut sync = Command::new(&self.uv);
            sync.args(["pip", "sync", "--quiet", "--python"])
                .arg(&python)
                .args(&plan.uv_args)
                .arg(&file);
            uv::run(sync, every, progress("installing the lock"))
                .map_err(|uv::Failed(m)| failed("`uv pip sync` of the lock", m))?;
        } else {
            let mut install = Command::new(&self.uv);
            install
                .args(["pip", "install", "--quiet", "--python"])
                .arg(&python)
                .args(&plan.uv_args)
                .args(&plan.requirements);
            uv::run(install, every, progress("installing"))
                .map_err(|uv::Failed(m)| failed("`uv pip install`", m))?;
            if !plan.no_deps.is_empty() {
                let mut bare = Command::new(&self.uv);
                bare.args(["pip", "install", "--quiet", "--no-deps", "--python"])
                    .arg(&python)
                    .args(&plan.uv_args)
                    .args(&plan.no_deps);
                uv::run(bare, every, progress("installing without dependencies"))
                    .map_err(|uv::Failed(m)| failed("`uv pip install --no-deps`", m))?;
            }
        }
        if !self.packages.is_empty() {
            let overlay = self.overlay(name)?;
            let modules: Vec<String> = self
                .packages
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            let mut check = Command::new(&python);
            // As its workers will: through this install's overlay.
            check.arg("-c").arg(format!(
                "import sys; sys.path.insert(0, {:?}); import {}",
                overlay.display().to_string(),
                modules.join(", ")
            ));
            uv::run(check, every, |_| {}).map_err(|uv::Failed(m)| {
                failed(
                    "importing envhub's worker package in the new env",
                    last_lines(&m, 6),
                )
            })?;
        }
        let mut freeze = Command::new(&self.uv);
        freeze.args(["pip", "freeze", "--python"]).arg(&python);
        let frozen =
            uv::run(freeze, every, |_| {}).map_err(|uv::Failed(m)| failed("`uv pip freeze`", m))?;
        let mut resolved: Vec<String> = frozen
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .map(String::from)
            .collect();
        resolved.sort();
        if let Some(pins) = &plan.locked {
            let normal = |list: &[String]| -> Vec<String> {
                let mut out: Vec<String> = list.iter().map(|p| normal_pin(p)).collect();
                out.sort();
                out
            };
            let (want, got) = (normal(pins), normal(&resolved));
            if want != got {
                let missing: Vec<&String> = want.iter().filter(|p| !got.contains(p)).collect();
                let extra: Vec<&String> = got.iter().filter(|p| !want.contains(p)).collect();
                return Err(failed(
                    "checking the venv against the lock",
                    format!(
                        "installed packages differ from the lock: missing {missing:?}, not in the lock {extra:?}"
                    ),
                ));
            }
        }
        let manifest = Manifest {
            name: name.clone(),
            key: plan.key.clone(),
            python_version: interpreter::version_of(&python).unwrap_or_default(),
            base_interpreter: plan.base.clone(),
            requirements: plan.requirements.clone(),
            no_deps: plan.no_deps.clone(),
            resolved,
            platform: plan.platform.clone(),
            locked: plan.locked.clone().unwrap_or_default(),
            created_unix: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .unwrap_or_default()
                .as_secs(),
            install_seconds: start.elapsed().as_secs_f64(),
        };
        let path = tmp.join(MANIFEST);
        let text = serde_json::to_string_pretty(&manifest).expect("a manifest serializes");
        std::fs::write(&path, text).map_err(io(name, "write", &path))
    }
}
