//! What a hub exposes to the network, decided before it opens its Zenoh session.
//!
//! A hub answers anyone who reaches it: it starts workers, runs envs and publishes their
//! observations. Without credentials it therefore listens on loopback only; listening on
//! another interface (or connecting out to one) without credentials takes an explicit
//! `--insecure-listen` and prints a warning. Credentials are Zenoh's own: user/password
//! (`transport/auth/usrpwd/dictionary_file`, checked on every link) or TLS with client
//! certificates (`transport/link/tls/enable_mtls` on `tls/` endpoints).

use envhub_protocol::HubError;
use std::net::IpAddr;

/// The listener a hub without credentials gets: loopback, a free port (found by local
/// clients through multicast scouting, or named with `--listen`).
pub const LOOPBACK_LISTENER: &str = "tcp/127.0.0.1:0";

/// Applies the exposure rule to a hub's Zenoh config. Returns what to tell the operator: the
/// warning when the hub is exposed without credentials because `insecure` allowed it, or how
/// to open it up when it was kept on loopback.
pub(crate) fn guard(
    config: &mut zenoh::Config,
    insecure: bool,
) -> Result<Option<String>, HubError> {
    let usrpwd = !is_null(&get(config, "transport/auth/usrpwd/dictionary_file"));
    let mtls = get(config, "transport/link/tls/enable_mtls") == "true";
    let mode =
        serde_json::from_str::<String>(&get(config, "mode")).unwrap_or_else(|_| "peer".into());
    // Zenoh's own default listener (every interface) counts as none given.
    let default_listen = get(&zenoh::Config::default(), "listen/endpoints");
    let listen_json = get(config, "listen/endpoints");
    let listen = if listen_json == default_listen {
        Vec::new()
    } else {
        endpoints(&listen_json, &mode)
    };
    let connect = endpoints(&get(config, "connect/endpoints"), &mode);
    let authenticated = |endpoint: &str| usrpwd || (mtls && protocol(endpoint) == "tls");
    let mut note = None;
    if listen.is_empty() && !usrpwd {
        config
            .insert_json5("listen/endpoints", &format!("[\"{LOOPBACK_LISTENER}\"]"))
            .map_err(|e| HubError::InvalidConfig {
                what: "zenoh config",
                reason: format!("cannot set the loopback listener: {e}"),
            })?;
        note = Some(
            "note: no credentials, so this hub listens on loopback only (this machine's clients); \
             to serve other machines give credentials with `--zenoh-config` and `--listen` \
             (docs/security.md), or `--insecure-listen` on a network you trust"
                .to_string(),
        );
    }
    let exposed: Vec<&String> = listen
        .iter()
        .chain(&connect)
        .filter(|e| !is_loopback(e) && !authenticated(e))
        .collect();
    if exposed.is_empty() {
        return Ok(note);
    }
    let list = exposed
        .iter()
        .map(|e| format!("`{e}`"))
        .collect::<Vec<_>>()
        .join(", ");
    if !insecure {
        return Err(HubError::InvalidConfig {
            what: "network exposure",
            reason: format!(
                "this hub would reach beyond this machine ({list}) without credentials: any peer \
                 there could open sessions, read their observations and send them actions\n\
                 hint: give credentials with `--zenoh-config` (user/password: \
                 `transport/auth/usrpwd`, or TLS with client certificates: `tls/` endpoints and \
                 `transport/link/tls/enable_mtls`; see docs/security.md), or pass \
                 `--insecure-listen` to do it anyway on a network you trust"
            ),
        });
    }
    Ok(Some(format!(
        "warning: this hub is open without credentials on {list} (`--insecure-listen`): any \
         peer that reaches it can run envs here and read or steer every session; see \
         docs/security.md"
    )))
}

fn get(config: &zenoh::Config, key: &str) -> String {
    config.get_json(key).unwrap_or_else(|_| "null".into())
}

fn is_null(json: &str) -> bool {
    matches!(json.trim(), "null" | "\"\"" | "")
}

/// The endpoints of a `listen`/`connect` value: a list, or a list per mode.
fn endpoints(json: &str, mode: &str) -> Vec<String> {
    match serde_json::from_str::<serde_json::Value>(json) {
        Ok(serde_json::Value::Array(items)) => items
            .into_iter()
            .filter_map(|v| v.as_str().map(String::from))
            .collect(),
        Ok(serde_json::Value::Object(map)) => map
            .get(mode)
            .map(|v| endpoints(&v.to_string(), mode))
            .unwrap_or_default(),
        _ => Vec::new(),
    }
}

fn protocol(endpoint: &str) -> &str {
    endpoint.split('/').next().unwrap_or_default()
}

/// Whether an endpoint (`tcp/127.0.0.1:7447`, `tls/[::1]:0`, `tcp/localhost:7447`) names a
/// loopback address. Anything unreadable counts as exposed.
fn is_loopback(endpoint: &str) -> bool {
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

    fn config(json5: &str) -> zenoh::Config {
        let mut c = zenoh::Config::default();
        for (key, value) in json5.lines().filter_map(|l| l.split_once('=')) {
            c.insert_json5(key.trim(), value.trim()).unwrap();
        }
        c
    }

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

    #[test]
    fn a_hub_without_credentials_listens_on_loopback_only() {
        let mut c = config("mode = \"peer\"");
        let note = guard(&mut c, false)
            .unwrap()
            .expect("a note on how to open it up");
        assert!(
            note.contains("loopback only") && note.contains("--insecure-listen"),
            "{note}"
        );
        assert_eq!(
            c.get_json("listen/endpoints").unwrap(),
            format!("[\"{LOOPBACK_LISTENER}\"]")
        );
    }

    #[test]
    fn listening_beyond_loopback_without_credentials_needs_the_flag() {
        let mut c = config("listen/endpoints = [\"tcp/0.0.0.0:7447\"]");
        let err = guard(&mut c, false).unwrap_err().to_string();
        assert!(
            err.contains("tcp/0.0.0.0:7447") && err.contains("--insecure-listen"),
            "{err}"
        );
        let warning = guard(&mut c, true).unwrap().expect("a warning");
        assert!(warning.contains("tcp/0.0.0.0:7447"), "{warning}");
        let mut c = config("connect/endpoints = [\"tcp/10.0.0.5:7447\"]");
        assert!(
            guard(&mut c, false).is_err(),
            "connecting out exposes the hub too"
        );
    }

    #[test]
    fn credentials_open_the_network() {
        let mut c = config(
            "listen/endpoints = [\"tcp/0.0.0.0:7447\"]\ntransport/auth/usrpwd/dictionary_file = \"/etc/envhub/users.txt\"",
        );
        assert_eq!(guard(&mut c, false).unwrap(), None);
        let mut c = config(
            "listen/endpoints = [\"tls/0.0.0.0:7447\", \"tcp/0.0.0.0:7448\"]\ntransport/link/tls/enable_mtls = true",
        );
        let err = guard(&mut c, false).unwrap_err().to_string();
        assert!(
            err.contains("tcp/0.0.0.0:7448") && !err.contains("tls/0.0.0.0:7447"),
            "mTLS covers tls/ only: {err}"
        );
    }
}
