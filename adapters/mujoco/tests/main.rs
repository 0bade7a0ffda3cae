//! The crate's one integration-test binary. Everything here needs libmujoco: without the
//! `libmujoco` feature it is empty.
#![cfg(feature = "libmujoco")]

mod conformance;
mod custom_mjcf;
mod gymnasium_parity;
mod render;
