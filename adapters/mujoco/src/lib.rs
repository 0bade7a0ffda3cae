//! MuJoCo in a Rust worker: Gymnasium 1.4's MuJoCo `-v5` suite (`mujoco` adapter) and custom
//! MJCF/URDF models (`custom_mjcf` adapter), on mujoco-rs 7 / MuJoCo 3.17.
//!
//! The trade-off: stepping natively keeps Python, the GIL and every copy out of the loop — an
//! env writes its float64 observation straight into the shared-memory slot it is handed — but
//! a native env is only worth having if it *is* Gymnasium's. So each task transcribes its
//! Gymnasium source (observation layout, reward terms, health checks, kwargs, info keys) on top
//! of the very same libmujoco build the `mujoco` wheel ships, steps it the way `MujocoEnv` does
//! (`mj_step` × `frame_skip`, then `mj_rnePostConstraint`), loads Gymnasium's own MJCF files from
//! the installed package, and draws reset noise with NumPy's generator
//! ([`envhub_core::NumpyRng`]), so a seed yields Gymnasium's initial state and a sequence of
//! actions its trajectory. A parity test against the installed Gymnasium catches drift; every
//! Gymnasium change must still be ported by hand.
//!
//! libmujoco is linked only with the `libmujoco` feature (which `envhub-worker`'s `mujoco`
//! feature turns on, and the Makefile turns on that). Without it this crate still builds, and
//! its adapters report themselves unavailable with the fix, so a machine without the library
//! builds and tests the rest of the workspace. Adding a task is one file in `tasks/` with an
//! `ENTRY` and one line in the list in `tasks/mod.rs` (and its id in `adapter.rs`).

mod adapter;
#[cfg(feature = "libmujoco")]
mod assets;
#[cfg(feature = "libmujoco")]
mod custom;
#[cfg(feature = "libmujoco")]
mod gym_env;
mod modes;
#[cfg(feature = "libmujoco")]
mod numeric;
#[cfg(feature = "libmujoco")]
mod obs;
#[cfg(feature = "libmujoco")]
mod render;
#[cfg(feature = "libmujoco")]
mod sim;
#[cfg(feature = "libmujoco")]
mod tasks;

pub use adapter::{
    AdapterInfo, CUSTOM_MJCF_INFO, CustomMjcf, LIBMUJOCO_VERSION, MUJOCO_INFO, Mujoco,
};
#[cfg(feature = "libmujoco")]
pub use gym_env::MujocoEnv;
