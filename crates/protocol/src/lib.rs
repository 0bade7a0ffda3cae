//! envhub's protocol: every message that crosses a process boundary between clients, hub
//! daemons, remote hubs and workers, with its validation, and the error type they carry.
//!
//! No I/O: encoding, decoding and checking bytes only, so both ends of each exchange depend
//! on this one crate (never one end on the other) and each parser can be tested and fuzzed
//! alone. The per-step byte layouts themselves (`RequestHeader`, `ResponseHeader`, the batch
//! blocks) are the data plane's, in `envhub-shm`; this crate frames them for the network.
//!
//! May depend on: `envhub-core`, `envhub-catalog` (its errors travel in [`HubError`]),
//! `envhub-shm` (layouts only), `ring` (the AEAD that seals session messages, and the key
//! exchange that agrees its key). Must not depend
//! on: Zenoh, iceoryx2 services, processes.

pub mod batch_codec;
pub mod daemon;
mod error;
mod frame;
pub mod handshake;
mod ids;
pub mod info_columns;
pub mod keys;
mod messages;
mod route;
pub mod seal;
pub mod untrusted;

pub use error::HubError;
pub use frame::Frame;
pub use ids::session_id;
pub use messages::{
    HubInfo, MAX_OPEN_REQUEST_BYTES, MAX_OPEN_REQUEST_DEPTH, MAX_OPEN_REQUEST_VALUES, OpenMessage,
    OpenReply, OpenRequest,
};
pub use route::Route;
