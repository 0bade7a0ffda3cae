//! Robot tasks on rapier3d, the pure-Rust physics engine: an arm reaching a target, an arm
//! pushing a puck to a goal, a quadruped running forward and a wheeled base driving to a goal
//! over seeded heightfield terrain.
//!
//! The trade-off: every task builds its robot in code from rapier primitives and impulse
//! joints instead of loading MuJoCo's MJCF files, so the tasks need nothing outside this
//! crate (no Python, no asset files) and are bit-for-bit deterministic (rapier's
//! `enhanced-determinism`, a fresh world per episode); the price is that they are modelled on
//! Gymnasium's tasks, not equal to them: same layouts and rewards in spirit, rapier's own
//! dynamics and actuator scales (see `docs/design/rapier.md`).
//!
//! Each task is one file in `tasks/` implementing `Task` plus one line in the adapter's list;
//! `TaskEnv` turns any task into an `envhub_core::Env`, and rendering is a ray caster over
//! rapier's own scene queries (`render.rs`).

mod adapter;
mod physics;
mod render;
mod task;
mod tasks;

pub use adapter::Rapier;
