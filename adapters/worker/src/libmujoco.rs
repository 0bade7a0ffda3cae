//! Finding libmujoco 3.17.0 at run time, and handing over to `envhub-worker-mujoco`.
//!
//! No binary carries a path of the machine it was built on (a wheel or `cargo install`
//! puts it elsewhere), so the library is looked up each time a worker starts:
//! `ENVHUB_MUJOCO_LIB` (a folder), else the `mujoco` package of the interpreter the hub passes
//! in `ENVHUB_PYTHON` (the PyPI wheel ships `mujoco/libmujoco.so.3.17.0`; `pip install
//! 'envhub[mujoco]'` pins it). The folder goes first on `envhub-worker-mujoco`'s
//! `LD_LIBRARY_PATH`. An `$ORIGIN`-relative RUNPATH would find the wheel only when `mujoco` sits
//! in the same `site-packages` as `envhub`, and a wrong or missing library would still be a
//! loader error; asking the interpreter covers any install (venv, user site, a `cargo
//! install`ed worker) and checks the version first.

use std::ffi::OsString;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The binary that links libmujoco, installed beside `envhub-worker`.
pub const MUJOCO_WORKER: &str = "envhub-worker-mujoco";

/// A folder holding `libmujoco.so.3.17.0`, instead of the interpreter's `mujoco` package
/// (declared with the other variables in `envhub_hub::env_vars`).
const ENVHUB_MUJOCO_LIB: &str = "ENVHUB_MUJOCO_LIB";

const HINT: &str = "pip install 'envhub[mujoco]' (it pins mujoco==3.17.0) into the Python that \
                    runs envhub, or set ENVHUB_PYTHON to a Python that has it (or \
                    ENVHUB_MUJOCO_LIB to a folder with libmujoco.so.3.17.0)";

/// Why libmujoco cannot be used, and the fix.
#[derive(Debug)]
pub struct Missing {
    /// What is wrong.
    pub reason: String,
    /// How to fix it.
    pub hint: String,
}

fn file_name() -> String {
    format!("libmujoco.so.{}", envhub_mujoco::LIBMUJOCO_VERSION)
}

/// The folder that holds libmujoco 3.17.0.
pub fn locate() -> Result<PathBuf, Missing> {
    let want = file_name();
    if let Some(dir) = std::env::var_os(ENVHUB_MUJOCO_LIB).filter(|d| !d.is_empty()) {
        let dir = PathBuf::from(dir);
        return if dir.join(&want).is_file() {
            Ok(dir)
        } else {
            Err(Missing {
                reason: format!("{ENVHUB_MUJOCO_LIB}=`{}` has no `{want}`", dir.display()),
                hint: HINT.into(),
            })
        };
    }
    let python = envhub_core::python_interpreter();
    let package = mujoco_package(&python)?;
    if package.join(&want).is_file() {
        return Ok(package);
    }
    let other: Vec<String> = std::fs::read_dir(&package)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.strip_prefix("libmujoco.so.").map(str::to_string)
        })
        .collect();
    Err(Missing {
        reason: if other.is_empty() {
            format!(
                "libmujoco {} not found: the `mujoco` package at `{}` has no `{want}`",
                envhub_mujoco::LIBMUJOCO_VERSION,
                package.display()
            )
        } else {
            format!(
                "libmujoco {} not found: `{}` has the `mujoco` package for libmujoco {}",
                envhub_mujoco::LIBMUJOCO_VERSION,
                python.display(),
                other.join(", ")
            )
        },
        hint: HINT.into(),
    })
}

/// The `mujoco` package folder of `python`: a look at its virtual environment's
/// `site-packages`, else the interpreter is asked (without importing the package).
fn mujoco_package(python: &Path) -> Result<PathBuf, Missing> {
    let not_found = |why: String| Missing {
        reason: format!(
            "libmujoco {} not found: {why}",
            envhub_mujoco::LIBMUJOCO_VERSION
        ),
        hint: HINT.into(),
    };
    if let Some(dir) = envhub_core::venv_site_packages(python)
        .into_iter()
        .map(|site| site.join("mujoco"))
        .find(|dir| dir.join("__init__.py").is_file())
    {
        return Ok(dir);
    }
    const PROBE: &str = "import importlib.util\n\
        s = importlib.util.find_spec('mujoco')\n\
        print(list(s.submodule_search_locations)[0] if s and s.submodule_search_locations else '')";
    let out = Command::new(python)
        .args(["-c", PROBE])
        .output()
        .map_err(|e| not_found(format!("cannot run `{}`: {e}", python.display())))?;
    let dir = String::from_utf8_lossy(&out.stdout).trim().to_string();
    if !out.status.success() || dir.is_empty() {
        return Err(not_found(format!(
            "`{}` has no `mujoco` package",
            python.display()
        )));
    }
    Ok(PathBuf::from(dir))
}

/// Replaces this process (same pid, same arguments) with `envhub-worker-mujoco` beside it,
/// with libmujoco's folder first on `LD_LIBRARY_PATH`; returns only when that cannot be done,
/// saying why.
pub fn hand_over() -> Missing {
    let exe = std::env::current_exe().unwrap_or_default();
    let full = exe.with_file_name(MUJOCO_WORKER);
    if !full.is_file() {
        return Missing {
            reason: format!(
                "no `{MUJOCO_WORKER}` beside `{}` (built without the `mujoco` feature, or a worker copied alone)",
                exe.display()
            ),
            hint:
                "run `make build` (it builds with `--features envhub-worker/mujoco`), or install \
                   with `cargo install --path crates/hub --features worker`; a worker named by \
                   ENVHUB_WORKER needs `envhub-worker-mujoco` beside it"
                    .into(),
        };
    }
    let dir = match locate() {
        Ok(dir) => dir,
        Err(missing) => return missing,
    };
    let mut path = OsString::from(dir);
    if let Some(old) = std::env::var_os("LD_LIBRARY_PATH").filter(|p| !p.is_empty()) {
        path.push(":");
        path.push(old);
    }
    let err = Command::new(&full)
        .args(std::env::args_os().skip(1))
        .env("LD_LIBRARY_PATH", path)
        .exec();
    Missing {
        reason: format!("cannot start `{}`: {err}", full.display()),
        hint: format!(
            "reinstall envhub: `{MUJOCO_WORKER}` must be an executable beside `envhub-worker`"
        ),
    }
}
