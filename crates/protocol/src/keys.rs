//! Zenoh key expressions of envhub, in one place.
//!
//! - `envhub/hub/<name>`: a hub's liveliness token (alive while the hub is).
//! - `envhub/hub/<name>/zid/<zid>`: its identity token, the Zenoh id its answers come from.
//! - `envhub/hub/<name>/{info,catalog,adapters,open}`: its queryables.
//! - `envhub/hub/<name>/echo/{req,rep}`: its echo (raw Zenoh round trips for benchmarks).
//! - `envhub/client/<id>`: a client's liveliness token; its sessions end when it goes.
//! - `envhub/session/<hub>/<session>/{req,rep}`: a session's requests and responses.

use crate::error::HubError;

/// Every hub's token.
pub const ALL_HUBS: &str = "envhub/hub/*";
/// Every hub's token and identity token.
pub const ALL_HUB_TOKENS: &str = "envhub/hub/**";
/// Every client's token.
pub const ALL_CLIENTS: &str = "envhub/client/*";

/// A hub's liveliness token.
pub fn hub_token(name: &str) -> String {
    format!("envhub/hub/{name}")
}

/// A hub's identity token: the Zenoh id (`Session::zid()`) that answers its queries. Clients
/// take answers to their queries of hub `name` only from that id.
pub fn hub_id_token(name: &str, zid: &str) -> String {
    format!("envhub/hub/{name}/zid/{zid}")
}

/// A hub's info queryable.
pub fn hub_info(name: &str) -> String {
    format!("envhub/hub/{name}/info")
}

/// A hub's catalog queryable.
pub fn hub_catalog(name: &str) -> String {
    format!("envhub/hub/{name}/catalog")
}

/// A hub's adapters queryable.
pub fn hub_adapters(name: &str) -> String {
    format!("envhub/hub/{name}/adapters")
}

/// A hub's queryable that opens sessions.
pub fn hub_open(name: &str) -> String {
    format!("envhub/hub/{name}/open")
}

/// A hub's echo: what is put on `.../echo/req` comes back on `.../echo/rep`, untouched (the raw
/// Zenoh round trip `envhub bench --hub` compares with).
pub fn hub_echo(name: &str) -> (String, String) {
    (
        format!("envhub/hub/{name}/echo/req"),
        format!("envhub/hub/{name}/echo/rep"),
    )
}

/// A client's liveliness token.
pub fn client_token(id: &str) -> String {
    format!("envhub/client/{id}")
}

/// A session's requests (client to hub).
pub fn requests(hub: &str, session: &str) -> String {
    format!("envhub/session/{hub}/{session}/req")
}

/// A session's responses (hub to client).
pub fn responses(hub: &str, session: &str) -> String {
    format!("envhub/session/{hub}/{session}/rep")
}

/// Requests of every session of `hub`.
pub fn all_requests(hub: &str) -> String {
    format!("envhub/session/{hub}/*/req")
}

/// The session named by a request key of `hub`, if the key is one.
pub fn session_of<'a>(hub: &str, key: &'a str) -> Option<&'a str> {
    key.strip_prefix("envhub/session/")?
        .strip_prefix(hub)?
        .strip_prefix('/')?
        .strip_suffix("/req")
        .filter(|s| !s.contains('/'))
}

/// The hub named by a token key.
pub fn hub_of_token(key: &str) -> Option<&str> {
    key.strip_prefix("envhub/hub/").filter(|s| !s.contains('/'))
}

/// The hub and Zenoh id named by an identity token's key.
pub fn hub_id_of_token(key: &str) -> Option<(&str, &str)> {
    let (name, zid) = key.strip_prefix("envhub/hub/")?.split_once("/zid/")?;
    (!name.contains('/') && !zid.is_empty() && !zid.contains('/')).then_some((name, zid))
}

/// A hub name must be one key chunk: no `/`, no wildcards, not empty.
pub fn check_name(name: &str) -> Result<(), HubError> {
    let bad = name.is_empty()
        || name
            .chars()
            .any(|c| matches!(c, '/' | '*' | '$' | '?' | '#' | '@') || c.is_whitespace());
    if bad {
        return Err(HubError::InvalidConfig {
            what: "hub name",
            reason: format!(
                "`{name}` is not a valid hub name; use letters, digits, `-`, `_` and `.` (no `/`, `*`, `$`, `?`, `#`, `@` or spaces)"
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip() {
        assert_eq!(session_of("a", &requests("a", "s1")), Some("s1"));
        assert_eq!(session_of("a", "envhub/session/ab/s1/req"), None);
        assert_eq!(session_of("a", "envhub/session/a/x/y/req"), None);
        assert_eq!(hub_of_token(&hub_token("box-1")), Some("box-1"));
        assert_eq!(hub_of_token(&hub_id_token("box-1", "ab12")), None);
        assert_eq!(
            hub_id_of_token(&hub_id_token("box-1", "ab12")),
            Some(("box-1", "ab12"))
        );
        assert_eq!(hub_id_of_token(&hub_token("box-1")), None);
        assert_eq!(hub_id_of_token("envhub/hub/a/zid/b/c"), None);
        assert!(check_name("box-1.lab").is_ok());
        assert!(check_name("a/b").is_err() && check_name("").is_err() && check_name("*").is_err());
    }
}
