//! Which Python interpreter a worker asks about installed packages (Gymnasium's MJCF assets,
//! the `mujoco` wheel's libmujoco): the hub passes its own in `ENVHUB_PYTHON`.

use std::path::{Path, PathBuf};

/// The interpreter variable (declared with the others in `envhub_hub::env_vars`).
const ENVHUB_PYTHON: &str = "ENVHUB_PYTHON";

/// `$ENVHUB_PYTHON`, else the nearest `.venv/bin/python` above the current directory or the
/// running binary (the project's own, which `make` creates), else `python3`.
pub fn python_interpreter() -> PathBuf {
    if let Some(p) = std::env::var_os(ENVHUB_PYTHON).filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    let mut starts: Vec<PathBuf> = Vec::new();
    if let Ok(dir) = std::env::current_dir() {
        starts.push(dir);
    }
    if let Ok(exe) = std::env::current_exe()
        && let Some(dir) = exe.parent()
    {
        starts.push(dir.to_path_buf());
    }
    for start in starts {
        for dir in start.ancestors() {
            let candidate = dir.join(".venv/bin/python");
            if candidate.is_file() {
                return candidate;
            }
        }
    }
    PathBuf::from("python3")
}

/// The `site-packages` folders of the virtual environment `python` belongs to
/// (`<venv>/bin/python`), where a look at the file system finds a package without starting
/// Python; empty for an interpreter outside a virtual environment.
pub fn venv_site_packages(python: &Path) -> Vec<PathBuf> {
    let Some(venv) = python.parent().and_then(Path::parent) else {
        return Vec::new();
    };
    if !venv.join("pyvenv.cfg").is_file() {
        return Vec::new();
    }
    let Ok(libs) = std::fs::read_dir(venv.join("lib")) else {
        return Vec::new();
    };
    libs.flatten()
        .map(|lib| lib.path().join("site-packages"))
        .filter(|site| site.is_dir())
        .collect()
}
