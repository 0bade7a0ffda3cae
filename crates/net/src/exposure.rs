//! What a hub or a client exposes to the network, decided before it opens its Zenoh session.
//!
//! A hub answers anyone who reaches it: it starts workers, runs envs and publishes their
//! observations. Without credentials it therefore listens on loopback only and neither scouts
//! nor answers scouts (multicast and gossip off: loopback carries no multicast, and a scout's
//! answer would tell the LAN it is there); listening on another interface without credentials
//! takes an explicit `--insecure-listen` and prints a warning. Credentials are Zenoh's own:
//! user/password (`transport/auth/usrpwd/dictionary_file`, checked on every link *into* the
//! hub) or TLS with client certificates (`transport/link/tls/enable_mtls` on `tls/`
//! endpoints, which checks both ends). A link the hub opens itself is authenticated only by
//! TLS with client certificates (user/password checks only who connects in), so a hub
//! connects out (`--connect`) beyond loopback only on such links, and never to what scouting
//! or gossip names (autoconnect off), unless `--insecure-listen`.
//!
//! A client runs no envs, but a peer it connects to can pass for a hub and read its actions:
//! it scouts and follows gossip only when told to (`multicast: true`, `ENVHUB_MULTICAST=1`)
//! or when TLS with client certificates checks every link; it connects to the endpoints it is
//! given and to the hubs of its own user on this machine ([`crate::local`]).

use crate::endpoint::{is_loopback, protocol};
use envhub_protocol::HubError;

/// The listener a hub without credentials gets: loopback, a free port (found by local
/// clients through [`crate::local`], or named with `--listen`).
pub const LOOPBACK_LISTENER: &str = "tcp/127.0.0.1:0";

/// What [`guard`] decided for a hub.
#[derive(Debug, Default, PartialEq, Eq)]
pub(crate) struct Exposure {
    /// What to tell the operator: a warning when open without credentials, or how to open up.
    pub notice: Option<String>,
    /// The hub listens on loopback only (local clients find it through [`crate::local`]).
    pub loopback_only: bool,
    /// Links into the hub must present this user's local credential ([`crate::local`]):
    /// loopback is open to every user of the machine, so a hub there without credentials of
    /// its own admits only its user's processes (unless `--insecure-listen` on a listener
    /// it was given).
    pub local_credential: bool,
    /// The endpoints the hub listens on.
    pub listen: Vec<String>,
}

/// The credentials a Zenoh config carries.
struct Credentials {
    /// User/password checked on links into this process.
    usrpwd_in: bool,
    /// TLS with client certificates: both ends of `tls/` links are checked.
    mtls: bool,
}

impl Credentials {
    fn of(config: &zenoh::Config) -> Credentials {
        Credentials {
            usrpwd_in: !is_null(&get(config, "transport/auth/usrpwd/dictionary_file")),
            mtls: get(config, "transport/link/tls/enable_mtls") == "true",
        }
    }

    /// Whether a link into this process on `endpoint` is authenticated.
    fn covers_in(&self, endpoint: &str) -> bool {
        self.usrpwd_in || (self.mtls && protocol(endpoint) == "tls")
    }

    /// Whether a link this process opens to `endpoint` authenticates the other end.
    fn covers_out(&self, endpoint: &str) -> bool {
        self.mtls && protocol(endpoint) == "tls"
    }
}

fn set(config: &mut zenoh::Config, key: &str, value: &str) -> Result<(), HubError> {
    config
        .insert_json5(key, value)
        .map_err(|e| HubError::InvalidConfig {
            what: "zenoh config",
            reason: format!("`{key}` = {value}: {e}"),
        })
}

/// Scouting off: neither multicast scouts (sent or answered) nor gossip.
fn no_scouting(config: &mut zenoh::Config) -> Result<(), HubError> {
    set(config, "scouting/multicast/enabled", "false")?;
    set(config, "scouting/gossip/enabled", "false")
}

/// Connects to nothing that scouting or gossip names (what it is given, only).
fn no_autoconnect(config: &mut zenoh::Config) -> Result<(), HubError> {
    set(config, "scouting/multicast/autoconnect", "[]")?;
    set(config, "scouting/gossip/autoconnect", "[]")
}

/// Applies the exposure rule to a hub's Zenoh config. `insecure`: `--insecure-listen`;
/// `scouting`: `--multicast-scouting`, the operator's explicit ask to send and answer
/// multicast scouts; `multicast`: what the config asked for (`multicast:`,
/// `ENVHUB_MULTICAST`; `None`: the default).
pub(crate) fn guard(
    config: &mut zenoh::Config,
    insecure: bool,
    scouting: bool,
    multicast: Option<bool>,
) -> Result<Exposure, HubError> {
    let credentials = Credentials::of(config);
    let mode =
        serde_json::from_str::<String>(&get(config, "mode")).unwrap_or_else(|_| "peer".into());
    // Zenoh's own default listener (every interface) counts as none given.
    let default_listen = get(&zenoh::Config::default(), "listen/endpoints");
    let listen_json = get(config, "listen/endpoints");
    let mut listen = if listen_json == default_listen {
        Vec::new()
    } else {
        endpoints(&listen_json, &mode)
    };
    let connect = endpoints(&get(config, "connect/endpoints"), &mode);
    let mut exposure = Exposure::default();
    if listen.is_empty() && !credentials.usrpwd_in {
        set(
            config,
            "listen/endpoints",
            &format!("[\"{LOOPBACK_LISTENER}\"]"),
        )?;
        listen = vec![LOOPBACK_LISTENER.to_string()];
        exposure.notice = Some(
            "note: no credentials, so this hub listens on loopback only (this machine's clients) \
             and neither sends nor answers multicast scouts; to serve other machines give \
             credentials with `--zenoh-config` and `--listen` (docs/design/security.md), or \
             `--insecure-listen` on a network you trust"
                .to_string(),
        );
    }
    exposure.loopback_only = listen.iter().all(|e| is_loopback(e));
    // A user/password dictionary of the operator's leaves no room for the local one (Zenoh
    // checks one); mTLS covers `tls/` listeners only.
    let uncredentialed = !credentials.usrpwd_in && listen.iter().any(|e| !credentials.covers_in(e));
    let assigned = listen == [LOOPBACK_LISTENER];
    exposure.local_credential = exposure.loopback_only && uncredentialed && (assigned || !insecure);
    exposure.listen = listen.clone();
    let exposed: Vec<&String> = listen
        .iter()
        .filter(|e| !is_loopback(e) && !credentials.covers_in(e))
        .chain(
            connect
                .iter()
                .filter(|e| !is_loopback(e) && !credentials.covers_out(e)),
        )
        .collect();
    if !exposed.is_empty() && !insecure {
        return Err(HubError::InvalidConfig {
            what: "network exposure",
            reason: format!(
                "this hub would reach beyond this machine ({}) without credentials that check \
                 both ends: any peer there could open sessions, read their observations and \
                 send them actions (user/password checks only the links into the hub; a hub \
                 connects out beyond loopback only on `tls/` with client certificates)\n\
                 hint: give credentials with `--zenoh-config` (user/password: \
                 `transport/auth/usrpwd`, or TLS with client certificates: `tls/` endpoints and \
                 `transport/link/tls/enable_mtls`; see docs/design/security.md), or pass \
                 `--insecure-listen` to do it anyway on a network you trust",
                quoted(&exposed)
            ),
        });
    }
    // Scouting and gossip name peers this hub has not authenticated: it connects to none, in
    // every mode (`--insecure-listen` included).
    no_autoconnect(config)?;
    let asked = scouting || multicast == Some(true);
    if exposure.loopback_only && asked {
        return Err(HubError::InvalidConfig {
            what: "network exposure",
            reason: "multicast scouting was asked for (`--multicast-scouting`, \
                     `multicast: true`, `ENVHUB_MULTICAST`), but this hub listens on loopback \
                     only: its scouts and answers would reach the whole LAN and name an \
                     address no one there can reach\n\
                     hint: leave multicast off (this machine's clients find the hub without \
                     it), or give credentials and `--listen` (docs/design/security.md)"
                .to_string(),
        });
    }
    // Without credentials on every listener, the hub scouts only when its operator says so
    // with the flag (an `ENVHUB_MULTICAST=1` exported for clients is not enough).
    let scouts = if exposure.loopback_only {
        false
    } else if uncredentialed {
        if multicast == Some(true) && !scouting {
            return Err(HubError::InvalidConfig {
                what: "network exposure",
                reason: "multicast scouting was asked for (`multicast: true`, \
                         `ENVHUB_MULTICAST=1`) on a hub without credentials: its answers would \
                         tell the whole LAN where to open sessions\n\
                         hint: pass `envhub serve --multicast-scouting` to do it anyway on a \
                         network you trust, or unset `ENVHUB_MULTICAST` for the hub"
                    .to_string(),
            });
        }
        scouting
    } else {
        multicast != Some(false)
    };
    if !scouts {
        no_scouting(config)?;
    } else {
        set(config, "scouting/multicast/enabled", "true")?;
    }
    if insecure && uncredentialed {
        let reach = if scouts {
            " and answers multicast scouts on the LAN (`--multicast-scouting`)"
        } else {
            "; it neither sends nor answers multicast scouts"
        };
        if exposed.is_empty() && exposure.loopback_only && !assigned {
            exposure.notice = Some(format!(
                "warning: this hub listens on {} without credentials (`--insecure-listen`): \
                 every user of this machine can run envs here{reach}; see docs/design/security.md",
                quoted(&listen.iter().collect::<Vec<_>>())
            ));
        } else if !exposed.is_empty() {
            exposure.notice = Some(format!(
                "warning: this hub is open without credentials on {} (`--insecure-listen`){reach}: \
                 any peer that reaches it can run envs here and read or steer every session; see \
                 docs/design/security.md",
                quoted(&exposed)
            ));
        }
    }
    Ok(exposure)
}

/// Applies the exposure rule to a client's Zenoh config: no scouting and no autoconnect
/// unless asked for (`multicast: Some(true)`) or TLS with client certificates checks every
/// link the client opens.
pub(crate) fn guard_client(
    config: &mut zenoh::Config,
    multicast: Option<bool>,
) -> Result<(), HubError> {
    let credentials = Credentials::of(config);
    let tls_only = get(config, "transport/link/protocols") == "[\"tls\"]";
    match multicast {
        Some(true) => Ok(()),
        Some(false) => {
            set(config, "scouting/multicast/enabled", "false")?;
            if credentials.mtls && tls_only {
                Ok(())
            } else {
                no_autoconnect(config)?;
                set(config, "scouting/gossip/enabled", "false")
            }
        }
        None if credentials.mtls && tls_only => Ok(()),
        None => {
            no_autoconnect(config)?;
            no_scouting(config)
        }
    }
}

fn quoted(endpoints: &[&String]) -> String {
    endpoints
        .iter()
        .map(|e| format!("`{e}`"))
        .collect::<Vec<_>>()
        .join(", ")
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
    fn a_hub_without_credentials_listens_on_loopback_only_and_scouts_nothing() {
        let mut c = config("mode = \"peer\"");
        let exposure = guard(&mut c, false, false, None).unwrap();
        let note = exposure.notice.expect("a note on how to open it up");
        assert!(
            note.contains("loopback only") && note.contains("--insecure-listen"),
            "{note}"
        );
        assert!(exposure.loopback_only);
        let get = |key: &str| c.get_json(key).unwrap();
        assert_eq!(
            get("listen/endpoints"),
            format!("[\"{LOOPBACK_LISTENER}\"]")
        );
        assert_eq!(get("scouting/multicast/enabled"), "false");
        assert_eq!(get("scouting/gossip/enabled"), "false");
        assert!(get("scouting/multicast/autoconnect").contains("[]"));
        assert!(get("scouting/gossip/autoconnect").contains("[]"));
        let mut c = config("mode = \"peer\"");
        let err = guard(&mut c, false, false, Some(true))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("multicast") && err.contains("loopback only"),
            "{err}"
        );
    }

    #[test]
    fn loopback_without_credentials_admits_only_this_users_processes() {
        let mut c = config("mode = \"peer\"");
        assert!(guard(&mut c, false, false, None).unwrap().local_credential);
        assert!(guard(&mut c, true, false, None).unwrap().local_credential);
        // A listener it was given, too: other users of the machine reach loopback.
        let given = "listen/endpoints = [\"tcp/127.0.0.1:7447\"]";
        let mut c = config(given);
        let exposure = guard(&mut c, false, false, None).unwrap();
        assert!(exposure.local_credential);
        assert_eq!(exposure.listen, ["tcp/127.0.0.1:7447"]);
        let mut c = config(given);
        let exposure = guard(&mut c, true, false, None).unwrap();
        assert!(!exposure.local_credential, "`--insecure-listen` shares it");
        let warning = exposure.notice.expect("a warning");
        assert!(
            warning.contains("tcp/127.0.0.1:7447") && warning.contains("every user"),
            "{warning}"
        );
        // The operator's credentials, or a listener beyond loopback: not a local hub.
        let usrpwd = "transport/auth/usrpwd/dictionary_file = \"/etc/envhub/users.txt\"";
        let mut c = config(&format!("{given}\n{usrpwd}"));
        assert!(!guard(&mut c, false, false, None).unwrap().local_credential);
        let mut c = config("listen/endpoints = [\"tcp/0.0.0.0:7447\"]");
        assert!(!guard(&mut c, true, false, None).unwrap().local_credential);
    }

    /// `--insecure-listen` opens listeners, not scouting: every mode keeps scouting and
    /// autoconnect off unless `--multicast-scouting` says otherwise, and the notice says so.
    #[test]
    fn insecure_listen_never_turns_scouting_or_autoconnect_back_on() {
        let off = |c: &zenoh::Config| {
            c.get_json("scouting/multicast/enabled").unwrap() == "false"
                && c.get_json("scouting/gossip/enabled").unwrap() == "false"
        };
        let no_autoconnect = |c: &zenoh::Config| {
            c.get_json("scouting/multicast/autoconnect")
                .unwrap()
                .contains("[]")
                && c.get_json("scouting/gossip/autoconnect")
                    .unwrap()
                    .contains("[]")
        };
        for given in [
            "mode = \"peer\"",
            "listen/endpoints = [\"tcp/127.0.0.1:7447\"]",
            "listen/endpoints = [\"tcp/0.0.0.0:7447\"]",
        ] {
            let mut c = config(given);
            let exposure = guard(&mut c, true, false, None).unwrap();
            assert!(
                off(&c) && no_autoconnect(&c),
                "{given}: scouting or autoconnect on"
            );
            if let Some(notice) = exposure.notice {
                assert!(
                    notice.contains("loopback only")
                        || notice.contains("neither sends nor answers"),
                    "{given}: {notice}"
                );
            }
            // `ENVHUB_MULTICAST=1` (meant for clients) does not open a hub without credentials.
            let mut c = config(given);
            let err = guard(&mut c, true, false, Some(true))
                .unwrap_err()
                .to_string();
            assert!(err.contains("multicast"), "{given}: {err}");
        }
        // The flag, beyond loopback: scouts on, autoconnect still off, and the warning says so.
        let mut c = config("listen/endpoints = [\"tcp/0.0.0.0:7447\"]");
        let exposure = guard(&mut c, true, true, None).unwrap();
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "true");
        assert!(no_autoconnect(&c));
        let warning = exposure.notice.unwrap();
        assert!(warning.contains("--multicast-scouting"), "{warning}");
        // On loopback the flag is refused: its answers would name an unreachable address.
        let mut c = config("mode = \"peer\"");
        assert!(guard(&mut c, true, true, None).is_err());
    }

    #[test]
    fn listening_beyond_loopback_without_credentials_needs_the_flag() {
        let mut c = config("listen/endpoints = [\"tcp/0.0.0.0:7447\"]");
        let err = guard(&mut c, false, false, None).unwrap_err().to_string();
        assert!(
            err.contains("tcp/0.0.0.0:7447") && err.contains("--insecure-listen"),
            "{err}"
        );
        let exposure = guard(&mut c, true, false, None).unwrap();
        let warning = exposure.notice.expect("a warning");
        assert!(warning.contains("tcp/0.0.0.0:7447"), "{warning}");
        let mut c = config("connect/endpoints = [\"tcp/10.0.0.5:7447\"]");
        assert!(
            guard(&mut c, false, false, None).is_err(),
            "connecting out exposes the hub too"
        );
    }

    #[test]
    fn credentials_open_the_network_only_where_they_check_both_ends() {
        let usrpwd = "transport/auth/usrpwd/dictionary_file = \"/etc/envhub/users.txt\"";
        let mut c = config(&format!(
            "listen/endpoints = [\"tcp/0.0.0.0:7447\"]\n{usrpwd}"
        ));
        let exposure = guard(&mut c, false, false, None).unwrap();
        assert_eq!(exposure.notice, None);
        assert!(!exposure.loopback_only);
        assert!(
            c.get_json("scouting/multicast/autoconnect")
                .unwrap()
                .contains("[]"),
            "a hub connects to nothing it scouts"
        );
        // User/password checks who connects in, not whom the hub connects to.
        let mut c = config(&format!(
            "listen/endpoints = [\"tcp/0.0.0.0:7447\"]\nconnect/endpoints = [\"tcp/10.0.0.9:7447\"]\n{usrpwd}"
        ));
        let err = guard(&mut c, false, false, None).unwrap_err().to_string();
        assert!(err.contains("tcp/10.0.0.9:7447"), "{err}");
        let mut c = config(
            "listen/endpoints = [\"tls/0.0.0.0:7447\", \"tcp/0.0.0.0:7448\"]\ntransport/link/tls/enable_mtls = true",
        );
        let err = guard(&mut c, false, false, None).unwrap_err().to_string();
        assert!(
            err.contains("tcp/0.0.0.0:7448") && !err.contains("tls/0.0.0.0:7447"),
            "mTLS covers tls/ only: {err}"
        );
        let mut c = config(
            "listen/endpoints = [\"tls/0.0.0.0:7447\"]\nconnect/endpoints = [\"tls/10.0.0.9:7447\"]\ntransport/link/tls/enable_mtls = true",
        );
        assert!(
            guard(&mut c, false, false, None).is_ok(),
            "mTLS covers links out"
        );
        // mTLS without a listener: Zenoh's default (tcp on every interface) is not covered.
        let mut c = config("transport/link/tls/enable_mtls = true");
        assert!(guard(&mut c, false, false, None).unwrap().loopback_only);
    }

    #[test]
    fn a_client_scouts_only_when_told_or_when_tls_checks_every_link() {
        let mut c = config("mode = \"peer\"");
        guard_client(&mut c, None).unwrap();
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(c.get_json("scouting/gossip/enabled").unwrap(), "false");
        let mut c = config("mode = \"peer\"");
        guard_client(&mut c, Some(true)).unwrap();
        assert_ne!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        let mut c =
            config("transport/link/tls/enable_mtls = true\ntransport/link/protocols = [\"tls\"]");
        guard_client(&mut c, None).unwrap();
        assert_ne!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
    }
}
