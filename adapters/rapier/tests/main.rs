//! The crate's one integration-test binary.

mod bad_input;
mod common;
mod conformance;
mod determinism;
mod rendering;
mod solvability;
