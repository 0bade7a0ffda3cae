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

/// Whether an endpoint (`tcp/127.0.0.1:7447`, `tls/[::1]:0`, `tcp/localhost:7447`) names a
/// loopback address. Anything unreadable counts as exposed.
pub(crate) fn is_loopback(endpoint: &str) -> bool {
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
        ] {
            assert!(!is_loopback(e), "{e}");
        }
    }
}
