//! Python environments for suites whose pins fight each other: each a venv of its own, built
//! on first need with uv and shared by every hub process of the user.
//!
//! The trade-off: a venv per distinct requirement set (keyed by a hash of it, in a per-user
//! cache folder) costs disk and a first install of minutes, and in return a suite's workers
//! run exactly the packages it pins, beside other suites' workers in the same session. uv does
//! the resolving and installing (and its cache makes a rebuild cheap); this crate names the
//! venvs, builds each once under a file lock, makes a build count only once it completed (a
//! temporary folder renamed into place), and reports what failed in uv's own words. It knows
//! nothing of the hub: the caller says where the cache is, which uv and interpreter to use,
//! and which package folders (envhub's own) to link into every venv.

mod error;
mod hold;
mod interpreter;
mod lock;
mod store;
mod uv;

pub use envhub_catalog::{
    EnvLock, LOCK_VERSION, LockFile, Locking, PythonEnvSpec, package_name, valid_name,
};
pub use error::PyEnvError;
pub use hold::shared_across_exec;
pub use interpreter::{Interpreter, version_of};
pub use store::{Manifest, Plan, PruneRule, Pruned, PythonEnv, Store, Stored};
pub use uv::{SETTINGS_VARS, find_uv, platform, settings as uv_settings};
