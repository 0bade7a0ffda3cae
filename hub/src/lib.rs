//! envhub: the environment registry, task matching and (soon) the hub and its client.
//!
//! The registry is plain data: RoboSmith-format YAML, loaded strictly (an unknown field or a
//! duplicate id is an error with file and line, never silently ignored) and searched in
//! memory. It is small (tens to hundreds of entries), so search is a linear scan that keeps
//! file order as the tie-breaker, which makes results predictable for people.

mod entry;
pub mod env_vars;
mod matching;
mod registry;
mod settings;
mod tags;

pub use entry::EnvEntry;
pub use matching::{Candidate, MatchError, TaskMatch, TaskSpec, match_task};
pub use registry::{DEFAULT_REGISTRY_NAME, Registry, RegistryError, SearchHit, SearchQuery};
pub use settings::{CONFIG_FILE_NAME, OneOrMany, Settings, SettingsError};
