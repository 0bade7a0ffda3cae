//! envhub's network: hubs across machines over Zenoh — discovery, the client's presence and
//! queries, the client's end of a remote session (an engine slice), and a hub's end of it
//! (a local session driven by messages).
//!
//! May depend on: `envhub-core`, `envhub-shm`, `envhub-protocol` (every message it sends),
//! `envhub-session` (the engine it plugs slices into and drives on the hub's side). Must not
//! depend on: the facade (the server that answers opens, placement) or Python.

mod bridge;
mod client;
mod config;
mod endpoint;
mod exposure;
pub mod identity;
pub mod lab;
mod link;
pub mod local;
mod opener;
mod policy;

pub use bridge::{Client, DROPPED, Refusal, Sessions, dispatch, new_session_id, start};
pub use client::{DISCOVERY, Network, unknown_hub};
pub use config::{
    DEFAULT_LEASE_MS, ENVHUB_CONNECT, ENVHUB_MULTICAST, HubSession, LocalEntry, NetConfig, open,
    open_hub,
};
pub use exposure::LOOPBACK_LISTENER;
pub use link::{RESENT, UNSEALED};
pub use opener::ZenohSlices;
pub use policy::{
    DEFAULT_IDLE_TIMEOUT, DEFAULT_MAX_ENVS, DEFAULT_MAX_REQUEST_BYTES,
    DEFAULT_MAX_SESSIONS_PER_CLIENT, DEFAULT_MAX_STEP_TIMEOUT, DEFAULT_WORKERS_PER_CORE,
    MAX_QUERIES_IN_FLIGHT, SESSION_QUEUE, ServePolicy, client_share,
};
