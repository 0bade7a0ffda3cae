//! Hubs across machines, over Zenoh.
//!
//! - `net`: the Zenoh settings every command and client shares.
//! - `serve`: a hub on the network (`envhub serve`): liveliness token, queryables, limits and
//!   the security policy for remote clients.
//! - `bridge`: the hub's side of a remote session — a local `VecEnv` driven by messages.
//! - `client`: a client's presence on the network: live hubs, queries, opening sessions.
//! - `link`: the client's end of one remote session, a link of a `VecEnv` like a worker.
//! - `wire`: the messages of a remote session (the data plane's byte layout, one per hub and
//!   round trip).
//! - `keys`: the key expressions.
//! - `untrusted`: checks of what a hub sends before the client uses it.

pub(crate) mod bridge;
pub(crate) mod client;
pub(crate) mod keys;
pub(crate) mod link;
pub mod net;
pub(crate) mod serve;
pub(crate) mod untrusted;
pub(crate) mod wire;
