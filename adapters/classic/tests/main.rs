//! The crate's one integration-test binary.

mod conformance;
mod gymnasium_parity;
