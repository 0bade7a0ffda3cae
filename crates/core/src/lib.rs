//! The envhub contract: what every adapter implements and every client relies on.
//!
//! This crate is the leaf of the workspace. It holds spaces, the `Env` and `EnvAdapter`
//! traits, `EnvConfig` and the error types, and nothing heavy: simulators, shared memory,
//! Zenoh and Python all live in crates that point here, so an adapter can be written and
//! tested without pulling any of them in.
//!
//! The one design choice that shapes everything: an env writes its observation into a byte
//! slice it is handed (laid out as [`Space::byte_len`] describes) instead of returning a
//! buffer, so the worker can hand it a slot inside a shared-memory sample and the data is
//! never copied after the simulator produces it.

mod adapter;
mod config;
mod env;
pub mod env_vars;
mod error;
mod framework;
#[cfg(feature = "logging")]
mod log_rate;
#[cfg(feature = "logging")]
mod logging;
mod numpy_rng;
pub mod private_dir;
mod python;
pub mod serde_text;
mod space;
mod suggest;
mod time_limit;

pub use adapter::{Availability, EnvAdapter, EnvSpec};
pub use config::{AutoresetMode, EnvConfig, ExtraKeys};
pub use env::{Env, Info, InfoValue, ResetOptions, Transition};
pub use error::{EnvError, did_you_mean};
pub use framework::{FRAMEWORKS, Framework, canonical_framework};
#[cfg(feature = "logging")]
pub use logging::init_logging;
pub use numpy_rng::NumpyRng;
pub use python::{python_interpreter, venv_site_packages};
pub use space::{BoundsCheck, DType, Space, SpaceError};
pub use suggest::closest;
pub use time_limit::TimeLimit;
