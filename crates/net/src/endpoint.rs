//! Zenoh endpoints (`tcp/127.0.0.1:7447`, `tls/[::1]:0#iface=lo`) read as envhub needs them:
//! their protocol and whether they stay on this machine.
//!
//! A module of its own because both `exposure` (what a hub opens up) and `local` (where this
//! user's hubs listen) read endpoints, and `local` must not lean on `exposure` for it:
//! `exposure`'s rules refer to `local`, so the two named each other.

use std::net::IpAddr;

/// The protocol an endpoint names (`tcp`, `tls`, ...).
pub(crate) fn protocol(endpoint: &str) -> &str {
    endpoint.split('/').next().unwrap_or_default()
}

/// Zenoh's protocol name for a Unix socket stream (`unixsock-stream//run/user/1000/x.sock`).
pub(crate) const UNIX_SOCKET: &str = "unixsock-stream";

/// The socket file a Unix-socket endpoint names (`unixsock-stream//a/b.sock`: `/a/b.sock`).
pub(crate) fn unix_socket_path(endpoint: &str) -> Option<&str> {
    let rest = endpoint.strip_prefix(UNIX_SOCKET)?.strip_prefix('/')?;
    let path = rest.split(['?', '#']).next().unwrap_or_default();
    path.starts_with('/').then_some(path)
}

/// Whether an endpoint (`tcp/127.0.0.1:7447`, `tls/[::1]:0`, `tcp/localhost:7447`) names a
/// loopback address, or a Unix socket (which no other machine reaches either). Anything
/// unreadable counts as exposed.
pub(crate) fn is_loopback(endpoint: &str) -> bool {
    if unix_socket_path(endpoint).is_some() {
        return true;
    }
    let address = endpoint
        .split_once('/')
        .map_or("", |(_, rest)| rest)
        .split(['?', '#'])
        .next()
        .unwrap_or_default();
    let host = match address.rsplit_once(':') {
        Some((host, port)) if port.chars().all(|c| c.is_ascii_digit()) => host,
        _ => return false,
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_addresses_are_recognised() {
        for e in [
            "tcp/127.0.0.1:7447",
            "tcp/[::1]:0",
            "tls/localhost:7447",
            "tcp/127.3.2.1:1#iface=lo",
            "unixsock-stream//run/user/1000/envhub/hubs/7.sock",
        ] {
            assert!(is_loopback(e), "{e}");
        }
        for e in [
            "tcp/0.0.0.0:7447",
            "tcp/[::]:0",
            "tcp/10.0.0.5:7447",
            "tcp/lab-host:7447",
            "garbage",
            "tcp/127.0.0.1",
            "unixsock-stream/relative.sock",
            "unixsock-streamx//a.sock",
        ] {
            assert!(!is_loopback(e), "{e}");
        }
        assert_eq!(
            unix_socket_path("unixsock-stream//a/b.sock#x=1"),
            Some("/a/b.sock")
        );
    }
}
