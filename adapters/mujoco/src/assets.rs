//! Finding Gymnasium's MJCF files: they ship inside the installed `gymnasium` package
//! (`gymnasium/envs/mujoco/assets/`), and are read from there rather than copied.
//!
//! The package is located once per process for the interpreter `$ENVHUB_PYTHON`, else the
//! nearest `.venv/bin/python` above the current directory or the running binary (the project's
//! own, which `make` creates), else `python3`. When that interpreter is a virtual environment's
//! and the package sits in its `site-packages`, a look at the file system finds it (a worker
//! starts a session without waiting for Python); otherwise the interpreter is asked where the
//! package is, without importing it (`importlib.util.find_spec`, a fraction of a second). The
//! adapter is reported unavailable without them, even for an env with an `asset_path`: a model
//! of one's own without Gymnasium is the `custom_mjcf` adapter's.

use envhub_core::{Availability, EnvError};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

const HINT: &str = "`make venv` installs gymnasium 1.4 into `.venv/`; or set ENVHUB_PYTHON to a \
                    Python that has it (a model file of your own runs without it: the \
                    `custom_mjcf` framework with an `asset_path`)";

/// `(reason, hint)` when the assets cannot be found.
type Missing = (String, String);

static ASSETS: OnceLock<Result<PathBuf, Missing>> = OnceLock::new();

const PROBE: &str = "\
import importlib.util, importlib.metadata, os
spec = importlib.util.find_spec('gymnasium')
if spec is None or not spec.submodule_search_locations:
    raise SystemExit('no module named gymnasium')
print(os.path.join(list(spec.submodule_search_locations)[0], 'envs', 'mujoco', 'assets'))
print(importlib.metadata.version('gymnasium'))
";

/// The assets and version of gymnasium in the `site-packages` of the virtual environment that
/// `python` belongs to (`<venv>/bin/python`), if it is there.
fn in_venv(python: &Path) -> Option<(PathBuf, String)> {
    for site in envhub_core::venv_site_packages(python) {
        let assets = site.join("gymnasium/envs/mujoco/assets");
        if !assets.join("ant.xml").is_file() {
            continue;
        }
        let version = std::fs::read_dir(&site)
            .ok()?
            .flatten()
            .find_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                name.strip_prefix("gymnasium-")?
                    .strip_suffix(".dist-info")
                    .map(str::to_string)
            })
            .unwrap_or_else(|| "?".into());
        return Some((assets, version));
    }
    None
}

fn locate() -> Result<PathBuf, Missing> {
    let python = envhub_core::python_interpreter();
    if let Some((dir, version)) = in_venv(&python) {
        warn_version(&version);
        return Ok(dir);
    }
    let out = Command::new(&python)
        .args(["-c", PROBE])
        .output()
        .map_err(|e| {
            (
                format!(
                    "cannot run `{}` to find gymnasium's MJCF assets: {e}",
                    python.display()
                ),
                HINT.to_string(),
            )
        })?;
    if !out.status.success() {
        let why = String::from_utf8_lossy(&out.stderr);
        return Err((
            format!(
                "`{}` has no gymnasium (for its MJCF assets): {}",
                python.display(),
                why.trim().lines().last().unwrap_or("")
            ),
            HINT.to_string(),
        ));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut lines = text.lines();
    let dir = PathBuf::from(lines.next().unwrap_or_default());
    let version = lines.next().unwrap_or("?");
    if !dir.join("ant.xml").is_file() {
        return Err((
            format!(
                "gymnasium {version} at `{}` has no MuJoCo assets",
                dir.display()
            ),
            HINT.to_string(),
        ));
    }
    warn_version(version);
    Ok(dir)
}

fn warn_version(version: &str) {
    if !version.starts_with("1.4.") {
        tracing::warn!(
            %version,
            "the MuJoCo envs follow gymnasium 1.4; the assets found belong to another version"
        );
    }
}

/// Gymnasium's MJCF folder, located once per process.
pub(crate) fn gymnasium_assets() -> Result<&'static Path, EnvError> {
    ASSETS
        .get_or_init(locate)
        .as_deref()
        .map_err(|(reason, hint)| EnvError::Unavailable {
            adapter: "mujoco".into(),
            reason: reason.clone(),
            hint: hint.clone(),
        })
}

/// The `mujoco` adapter's availability: libmujoco is linked (or this would not run), so it is
/// whether the assets can be found.
pub(crate) fn availability() -> Availability {
    match ASSETS.get_or_init(locate) {
        Ok(_) => Availability::Available,
        Err((reason, hint)) => Availability::Unavailable {
            reason: reason.clone(),
            hint: hint.clone(),
        },
    }
}

/// Gymnasium's `expand_model_path`: a path starting with `/` or `.` as given, `~` expanded,
/// anything else a file of the assets folder.
pub(crate) fn model_path(xml_file: &str) -> Result<PathBuf, EnvError> {
    if xml_file.starts_with('/') || xml_file.starts_with('.') {
        Ok(PathBuf::from(xml_file))
    } else if let Some(rest) = xml_file.strip_prefix('~') {
        let home = std::env::var_os("HOME").unwrap_or_default();
        Ok(PathBuf::from(home).join(rest.trim_start_matches('/')))
    } else {
        Ok(gymnasium_assets()?.join(xml_file))
    }
}
