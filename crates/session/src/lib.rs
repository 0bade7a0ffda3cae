//! envhub's session engine: a batch of envs spread over workers and stepped through shared
//! memory — batch slots, worker links, results, lock-step and asynchronous steps.
//!
//! It runs sets of envs that answer a batch, whatever they are: local worker processes over
//! iceoryx2, started through [`Launch`] (the layer above decides by whom and with which
//! interpreter), and slices on other hubs through [`RemoteSlice`] / [`SliceOpener`] (the
//! network crate implements them). So the engine names neither Zenoh nor placement policy,
//! and it can be driven and tested with local workers alone.
//!
//! May depend on: `envhub-core`, `envhub-shm`, `envhub-protocol`. Must not depend on: Zenoh,
//! the catalog's files, the facade.

mod async_step;
mod batch;
mod collect;
mod env;
mod env_pool;
mod env_pool_state;
mod lanes;
mod launch;
mod remote;
mod results;
mod session_options;
mod vec_env;
mod worker_link;

pub use batch::Batch;
pub use env::{Env, Step};
pub use envhub_protocol::Frame;
pub use launch::{Launch, Process};
pub use remote::{LOCAL, RemoteSlice, Slice, SliceOpener};
pub use session_options::{SessionOptions, cores, seconds_from_env, workers_for};
pub use vec_env::{StartPlan, VecEnv};
pub use worker_link::InterruptCheck;
