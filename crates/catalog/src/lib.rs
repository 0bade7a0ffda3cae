//! envhub's catalog: registry files, their entries and tags, search and task matching.
//!
//! Pure logic over plain data. The registry is RoboSmith-format YAML, loaded strictly (an
//! unknown field or a duplicate id is an error with file and line, never silently ignored)
//! and searched in memory. It is small (tens to hundreds of entries), so search is a linear
//! scan that keeps file order as the tie-breaker, which makes results predictable for people.
//!
//! May depend on: `envhub-core` (frameworks, suggestions). Must not depend on: shared memory,
//! processes, the network or Python (`scripts/check_layers.py` enforces it), so a search or a
//! match (`envhub.get`, `envhub.search`, the CLI's `envs`/`match`) needs none of them.

mod builtin_assets;
mod entry;
mod env_lock;
mod matching;
mod python_env_spec;
mod python_envs;
mod registry;
mod registry_error;
mod tags;

pub use entry::EnvEntry;
pub use env_lock::{EnvLock, LOCK_VERSION, LockFile, Locking, lock_path};
pub use matching::{Candidate, MatchError, TaskMatch, TaskSpec, match_task};
pub use python_env_spec::{PythonEnvSpec, fnv1a64, package_name, parse_version, valid_name};
pub use python_envs::{FrameworkDefaults, PythonEnvs};
pub use registry::{
    Benchmark, DEFAULT_REGISTRY_NAME, LockSource, Registry, RegistryError, SearchHit, SearchQuery,
};
