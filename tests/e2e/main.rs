//! End-to-end tests: real worker processes, real iceoryx2 shared memory.

mod actions;
mod async_step;
mod bad_input;
mod classic_rollouts;
mod cli;
mod concurrency;
mod daemon;
mod failures;
mod hub_bounds;
mod lan_peer;
mod local_files;
mod lying_hub;
mod other_user;
mod python_worker;
mod rapier_rollouts;
mod remote_hubs;
mod remote_impostor;
mod remote_netns;
mod rendering;
mod serve_defaults;
mod session_owner;
mod small_shm;
mod tls;
mod worker_binaries;
mod worker_lifetime;
