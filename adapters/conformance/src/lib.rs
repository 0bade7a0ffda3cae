//! Test support that every adapter crate shares as a dev-dependency: the `Env` contract checks
//! ([`check_env`]) and the runner for the Python scripts that record Gymnasium's own
//! trajectories ([`python_reference`]), with the small numeric helpers the parity tests use.
//!
//! The trade-off: the checks are written once, against `EnvAdapter` and `Env` only, so an
//! adapter gets all of them with one line per env and none can quietly check less than
//! another; what legitimately differs between adapters (the config, hence the episode limit,
//! and the rollout length) is a parameter the call site states, never a copy. Replaying a
//! reference stays in each adapter's own parity test, since what a simulator state is (a few
//! numbers, `qpos`/`qvel`) differs per adapter.
//!
//! Panics are the interface: these functions are meant to be called from a `#[test]`, and the
//! ones that check are `#[track_caller]`, so a failure points at the adapter's test line.

mod checks;
mod reference;

pub use checks::check_env;
pub use reference::{close, floats, gymnasium_version, python_reference, scaled_diff};
