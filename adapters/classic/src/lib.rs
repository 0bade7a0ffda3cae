//! Gymnasium 1.4's classic-control envs — `CartPole-v1`, `Pendulum-v1`, `MountainCar-v0`,
//! `MountainCarContinuous-v0`, `Acrobot-v1` — in pure Rust, behind the `classic_control`
//! adapter.
//!
//! The trade-off: a native port steps in nanoseconds with no Python, GIL or copy in the loop,
//! but it is only worth having if it *is* Gymnasium. So each env transcribes Gymnasium's
//! arithmetic operation for operation rather than re-deriving the physics: the same evaluation
//! order, float64 where NumPy computes in float64 and float32 where NumPy's scalar promotion
//! drops to float32 (Pendulum's torque terms, MountainCarContinuous after its first step), and
//! NumPy's own `SeedSequence` + `PCG64` generator so that a seed yields Gymnasium's initial state
//! bit for bit. The price is that every Gymnasium change must be ported by hand and that only
//! what was ported exists (no rendering, no `book_or_nips` or torque noise for Acrobot); a
//! parity test against the installed Gymnasium (`tests/gymnasium_parity.rs`) catches drift.
//!
//! Each env exposes its full state through [`ClassicEnv`] (`state`/`set_state`), which the
//! parity test uses to replay Gymnasium's trajectories. Adding an env is one file with an
//! `ENTRY` and one line in the list in `adapter.rs`.

mod acrobot;
mod adapter;
mod cartpole;
mod classic_env;
mod layout;
mod mountain_car;
mod mountain_car_continuous;
mod numeric;
mod pendulum;
mod reset_options;
mod rng;

pub use acrobot::Acrobot;
pub use adapter::ClassicControl;
pub use cartpole::CartPole;
pub use classic_env::ClassicEnv;
pub use mountain_car::MountainCar;
pub use mountain_car_continuous::MountainCarContinuous;
pub use pendulum::Pendulum;
