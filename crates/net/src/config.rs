//! How a process reaches other hubs: the Zenoh settings shared by `envhub serve`, the CLI and
//! the clients (`--connect`, `--listen`, `--zenoh-config`, `ENVHUB_CONNECT`, `zenoh:` in
//! `envhub.yaml`), turned into a Zenoh config.

use envhub_protocol::HubError;
use serde::Deserialize;
use std::path::PathBuf;

/// Comma-separated Zenoh endpoints to connect to (`tcp/10.0.0.5:7447,tcp/10.0.0.6:7447`),
/// added to the config's and the command line's.
pub const ENVHUB_CONNECT: &str = "ENVHUB_CONNECT";

/// `0` turns multicast scouting off, `1` on (a client on a trusted LAN; see
/// [`crate::exposure`]).
pub const ENVHUB_MULTICAST: &str = "ENVHUB_MULTICAST";

/// Lease of this process's Zenoh links, in milliseconds. A peer that holds a liveliness token
/// and stops answering (frozen, cut off) is declared gone after about this long; Zenoh's
/// default (10 s) is far beyond the 2 s envhub promises. Four keep-alives per lease leave
/// room for a loaded machine: a 750 ms stall does not expire a link.
pub const DEFAULT_LEASE_MS: u64 = 1000;

/// The `zenoh:` section of `envhub.yaml`, and what the command line and environment add.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NetConfig {
    /// Endpoints to connect to (`tcp/host:7447`): hubs or a `zenohd` router.
    pub connect: Vec<String>,
    /// Endpoints to listen on (a hub's default: Zenoh's, every interface on a free port).
    pub listen: Vec<String>,
    /// A standard Zenoh JSON5 config (router, TLS, credentials); the other fields are applied
    /// on top of it.
    pub config: Option<PathBuf>,
    /// Multicast scouting and gossip, to find hubs on the LAN (default: off without
    /// credentials that check both ends, see [`crate::exposure`]; `ENVHUB_MULTICAST=1` turns
    /// it on for a client on a network it trusts).
    pub multicast: Option<bool>,
    /// Link lease in milliseconds (default [`DEFAULT_LEASE_MS`]).
    pub lease_ms: Option<u64>,
    /// The file of hub identities this client pinned (default: `ENVHUB_KNOWN_HUBS`, else
    /// `known_hubs` in `~/.config/envhub`; see [`crate::identity`]).
    pub known_hubs: Option<PathBuf>,
}

impl NetConfig {
    /// Adds the command line's endpoints and config file, and `ENVHUB_CONNECT`'s endpoints.
    pub fn with_overrides(
        mut self,
        connect: &[String],
        listen: &[String],
        config: Option<&std::path::Path>,
    ) -> NetConfig {
        self.connect.extend(connect.iter().cloned());
        if let Ok(var) = std::env::var(ENVHUB_CONNECT) {
            self.connect.extend(
                var.split(',')
                    .map(str::trim)
                    .filter(|s| !s.is_empty())
                    .map(String::from),
            );
        }
        self.listen.extend(listen.iter().cloned());
        if let Some(path) = config {
            self.config = Some(path.to_path_buf());
        }
        if let Ok(v) = std::env::var(ENVHUB_MULTICAST) {
            self.multicast = Some(!matches!(v.trim(), "0" | "false" | "off" | "no"));
        }
        self.connect.dedup();
        self
    }

    /// The Zenoh config: the file's (if any) with envhub's settings on top. `listen_default`:
    /// whether to keep Zenoh's default listener when no endpoint is given (hubs listen, so
    /// peers can reach them; clients only connect out).
    pub fn zenoh_config(&self, listen_default: bool) -> Result<zenoh::Config, HubError> {
        let invalid = |reason: String| HubError::InvalidConfig {
            what: "zenoh config",
            reason,
        };
        let mut config = match &self.config {
            Some(path) => zenoh::Config::from_file(path).map_err(|e| {
                invalid(format!(
                    "cannot use `{}`: {e}\nhint: a Zenoh JSON5 config, as `zenohd` reads",
                    path.display()
                ))
            })?,
            None => zenoh::Config::default(),
        };
        let default_listener = listens_by_default(&config);
        let mut set = |key: &str, value: String| {
            config
                .insert_json5(key, &value)
                .map_err(|e| invalid(format!("`{key}` = {value}: {e}")))
        };
        if self.config.is_none() {
            set("mode", "\"peer\"".into())?;
        }
        if !self.connect.is_empty() {
            set("connect/endpoints", json_list(&self.connect))?;
        }
        if !self.listen.is_empty() {
            set("listen/endpoints", json_list(&self.listen))?;
        } else if !listen_default && default_listener {
            // A client connects out only, also when its config file (TLS, credentials) says
            // nothing of listening.
            set("listen/endpoints", "[]".into())?;
        }
        if let Some(on) = self.multicast {
            set("scouting/multicast/enabled", on.to_string())?;
        }
        let lease = self.lease_ms.unwrap_or(DEFAULT_LEASE_MS);
        set("transport/link/tx/lease", lease.to_string())?;
        set("transport/link/tx/keep_alive", "4".into())?;
        Ok(config)
    }
}

/// Whether `config` keeps Zenoh's default listener (every interface).
fn listens_by_default(config: &zenoh::Config) -> bool {
    let listen = |c: &zenoh::Config| c.get_json("listen/endpoints").ok();
    listen(config) == listen(&zenoh::Config::default())
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).expect("strings serialize")
}

/// How long a link into a hub may take to say who it is, in milliseconds (Zenoh's default:
/// 10 s). A real peer does it within a round trip or two.
pub const ACCEPT_TIMEOUT_MS: u64 = 2000;
/// The fewest links into a hub being accepted at once (Zenoh's default: 100, which 150 idle
/// connections of another user filled, locking the owner's clients out). A hub takes as many
/// as its open files allow ([`accept_pending`]): an idle link holds a file either way.
pub const ACCEPT_PENDING: usize = 4096;
/// Open files a hub keeps for itself (workers, shared memory, sessions) when it sizes its
/// queue of links being accepted.
const RESERVED_FILES: u64 = 1024;

/// Raises this process's soft limit of open files to at least `wanted` (within the hard
/// limit): a hub holds a file per link it is accepting. Returns the soft limit now.
fn raise_open_files(wanted: u64) -> u64 {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit with a valid resource and a pointer to a local struct.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) != 0 {
            return 0;
        }
        if limit.rlim_cur >= wanted {
            return limit.rlim_cur;
        }
        let now = limit.rlim_cur;
        limit.rlim_cur = wanted.min(limit.rlim_max);
        if libc::setrlimit(libc::RLIMIT_NOFILE, &limit) != 0 {
            tracing::warn!(
                wanted,
                "cannot raise the limit of open files: many idle links could lock clients out"
            );
            return now;
        }
        limit.rlim_cur
    }
}

/// The queue of links being accepted for a hub that may hold `files` open files: all but
/// [`RESERVED_FILES`] of them, and at least [`ACCEPT_PENDING`]. Past the queue Zenoh closes
/// every new link, the owner's included; past the files the kernel does. Either way an
/// attacker must hold that many silent connections, each for ACCEPT_TIMEOUT_MS at most.
fn accept_pending(files: u64) -> usize {
    usize::try_from(files.saturating_sub(RESERVED_FILES))
        .unwrap_or(usize::MAX)
        .max(ACCEPT_PENDING)
}

/// A hub's Zenoh session and what its exposure rule decided.
pub struct HubSession {
    /// The session.
    pub session: zenoh::Session,
    /// What to print at start: the warning when the hub is open to the network without
    /// credentials, or how to open it up when it was kept on loopback.
    pub notice: Option<String>,
    /// Its entry among this machine's hubs (loopback only), to write once the hub answers.
    pub local: Option<LocalEntry>,
}

/// A loopback hub's entry among this machine's hubs, not yet written: the file tells this
/// user's clients the hub is there, so it is written only once the hub's tokens and
/// queryables are declared (a client that reads it sooner could give up before the hub
/// answers).
pub struct LocalEntry {
    name: String,
    endpoints: Vec<String>,
}

impl LocalEntry {
    fn new(name: &str, endpoints: &[String]) -> LocalEntry {
        LocalEntry {
            name: name.to_string(),
            endpoints: endpoints.to_vec(),
        }
    }

    /// Writes the entry; it is removed when the result is dropped. A failure is a warning
    /// (the hub still serves clients that name its endpoint).
    pub fn publish(self) -> Option<crate::local::Published> {
        crate::local::publish(&self.name, &self.endpoints)
            .inspect_err(|e| {
                tracing::warn!(
                    "this machine's clients will not find this hub without `--connect {}`: {e}",
                    self.endpoints.join(",")
                )
            })
            .ok()
    }
}

/// Opens hub `name`'s Zenoh session: listening on loopback only (and found by this user's
/// clients through [`crate::local`]) unless credentials are configured or the policy's
/// `insecure_listen` allows it (see [`crate::exposure`]).
pub fn open_hub(
    name: &str,
    net: &NetConfig,
    policy: &crate::ServePolicy,
) -> Result<HubSession, HubError> {
    use zenoh::Wait;
    let mut config = net.zenoh_config(true)?;
    let exposure = crate::exposure::guard(
        &mut config,
        policy.insecure_listen,
        policy.multicast_scouting,
        net.multicast,
    )?;
    // Zenoh drops larger messages before they reach envhub. Links that connect and say
    // nothing (held open by anyone who reaches the port) wait at most ACCEPT_TIMEOUT_MS in
    // the queue of links being accepted: past it Zenoh closes new links at once, the owner's
    // clients' included. A link waiting there, and on TLS every handshake under way (which
    // no queue bounds), holds an open file: the hub raises its limit to the hard one (at
    // most Linux's default `nr_open`) and sizes the queue to it.
    let files = raise_open_files(1 << 20);
    for (key, value) in [
        (
            "transport/link/rx/max_message_size",
            policy.max_request_bytes.to_string(),
        ),
        (
            "transport/unicast/accept_timeout",
            ACCEPT_TIMEOUT_MS.to_string(),
        ),
        (
            "transport/unicast/accept_pending",
            accept_pending(files).to_string(),
        ),
    ] {
        config
            .insert_json5(key, &value)
            .map_err(|e| HubError::InvalidConfig {
                what: "zenoh config",
                reason: format!("`{key}`: {e}"),
            })?;
    }
    let default_listener = config.get_json("listen/endpoints").ok()
        == Some(format!("[\"{}\"]", crate::LOOPBACK_LISTENER));
    if exposure.local_credential {
        check_local_credential(&mut config)?;
    }
    present_local_credential(&mut config, net)?;
    if !default_listener {
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| open_failed(net, e))?;
        let local = exposure
            .local_credential
            .then(|| LocalEntry::new(name, &exposure.listen));
        return Ok(HubSession {
            session,
            notice: exposure.notice,
            local,
        });
    }
    // This user's local hub, listening on one endpoint it lists in the folder of local hubs.
    let local_hub = |session, endpoint: String, notice| HubSession {
        session,
        notice,
        local: Some(LocalEntry::new(name, &[endpoint])),
    };
    // A Unix socket in the folder of local hubs, which only this user can reach: no other
    // user's connections can fill its queue of links being accepted (docs/design/security.md).
    if let Some(endpoint) = crate::local::socket_endpoint() {
        match open_listening_on(&config, &endpoint)? {
            Ok(session) => return Ok(local_hub(session, endpoint, exposure.notice)),
            Err(e) => tracing::warn!(
                %endpoint,
                error = %e,
                "cannot listen on a Unix socket: this hub listens on a loopback TCP port"
            ),
        }
    }
    // Else loopback on a port of its own choosing, so it can tell local clients which: a port
    // taken between the choice and the listen is chosen again.
    let mut tries = 0;
    loop {
        tries += 1;
        let endpoint = format!(
            "tcp/127.0.0.1:{}",
            crate::local::free_port().map_err(|e| HubError::Network {
                reason: format!("no free loopback port: {e}"),
                hint: "check the machine's loopback interface".into(),
            })?
        );
        match open_listening_on(&config, &endpoint)? {
            Ok(session) => return Ok(local_hub(session, endpoint, exposure.notice)),
            Err(e) if tries >= 3 => return Err(open_failed(net, e)),
            Err(e) => tracing::debug!(%endpoint, error = %e, "loopback port taken: another"),
        }
    }
}

/// Opens a Zenoh session of `config` listening on `endpoint` alone: the outer error is a
/// config Zenoh refuses, the inner one the open's (an endpoint taken, say).
fn open_listening_on(
    config: &zenoh::Config,
    endpoint: &str,
) -> Result<zenoh::Result<zenoh::Session>, HubError> {
    use zenoh::Wait;
    let mut config = config.clone();
    config
        .insert_json5("listen/endpoints", &json_list(&[endpoint.to_string()]))
        .map_err(|e| HubError::InvalidConfig {
            what: "zenoh config",
            reason: format!("`listen/endpoints`: {e}"),
        })?;
    Ok(zenoh::open(config).wait())
}

/// Loopback is open to every user of the machine: links into this hub must present this
/// user's local credential, which only this user's processes can read.
fn check_local_credential(config: &mut zenoh::Config) -> Result<(), HubError> {
    let credential = crate::local::credential().map_err(|e| HubError::Network {
        reason: format!("cannot make this user's local credential: {e}"),
        hint: "the folder of local hubs (`ENVHUB_LOCAL_HUBS`, else `hubs/` in \
               `$XDG_RUNTIME_DIR/envhub` or `~/.cache/envhub/run`) must be this user's alone; \
               or give credentials (docs/design/security.md)"
            .into(),
    })?;
    config
        .insert_json5(
            "transport/auth/usrpwd/dictionary_file",
            &serde_json::to_string(&credential.dictionary.to_string_lossy())
                .expect("strings serialize"),
        )
        .map_err(|e| HubError::InvalidConfig {
            what: "zenoh config",
            reason: format!("`transport/auth/usrpwd/dictionary_file`: {e}"),
        })
}

fn open_failed(net: &NetConfig, e: zenoh::Error) -> HubError {
    HubError::Network {
        reason: format!("cannot open a Zenoh session: {e}"),
        hint: format!(
            "check the endpoints (connect {:?}, listen {:?}) and the config file {:?}",
            net.connect, net.listen, net.config
        ),
    }
}

/// Opens a client's Zenoh session (see [`crate::exposure::guard_client`]), naming the
/// endpoints on failure.
pub fn open(net: &NetConfig, listen_default: bool) -> Result<zenoh::Session, HubError> {
    use zenoh::Wait;
    let mut config = net.zenoh_config(listen_default)?;
    crate::exposure::guard_client(&mut config, net.multicast)?;
    present_local_credential(&mut config, net)?;
    zenoh::open(config).wait().map_err(|e| open_failed(net, e))
}

/// A client that connects only to this user's local hubs presents this user's local
/// credential (those hubs refuse links without it). Only then: Zenoh's user/password makes
/// a link fail where the other end checks none, and one session has one credential.
fn present_local_credential(config: &mut zenoh::Config, net: &NetConfig) -> Result<(), HubError> {
    let given = config
        .get_json("transport/auth/usrpwd/user")
        .is_ok_and(|v| !matches!(v.trim(), "null" | "\"\""));
    if given || net.connect.is_empty() {
        return Ok(());
    }
    let local = crate::local::endpoints();
    if !net.connect.iter().all(|e| local.contains(e)) {
        return Ok(());
    }
    let credential = match crate::local::credential() {
        Ok(c) => c,
        Err(e) => {
            tracing::warn!("this user's local hubs will refuse this client: {e}");
            return Ok(());
        }
    };
    for (key, value) in [
        ("transport/auth/usrpwd/user", crate::local::LOCAL_USER),
        (
            "transport/auth/usrpwd/password",
            credential.password.as_str(),
        ),
    ] {
        config
            .insert_json5(
                key,
                &serde_json::to_string(value).expect("strings serialize"),
            )
            .map_err(|e| HubError::InvalidConfig {
                what: "zenoh config",
                reason: format!("`{key}`: {e}"),
            })?;
    }
    Ok(())
}

impl NetConfig {
    /// This config with this user's local hubs added as endpoints, when it names no
    /// endpoint and no Zenoh config of its own ([`crate::local`]).
    pub fn with_local_hubs(&self) -> NetConfig {
        let mut net = self.clone();
        if net.connect.is_empty() && net.config.is_none() {
            net.connect = crate::local::endpoints();
        }
        net
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_multicast_and_lease_reach_the_zenoh_config() {
        let net = NetConfig {
            connect: vec!["tcp/127.0.0.1:17999".into()],
            multicast: Some(false),
            lease_ms: Some(2500),
            ..NetConfig::default()
        };
        let config = net.zenoh_config(false).unwrap();
        let get = |key: &str| config.get_json(key).unwrap();
        assert_eq!(get("connect/endpoints"), r#"["tcp/127.0.0.1:17999"]"#);
        assert_eq!(get("listen/endpoints"), "[]", "a client listens on nothing");
        assert_eq!(get("scouting/multicast/enabled"), "false");
        assert_eq!(get("transport/link/tx/lease"), "2500");
    }

    #[test]
    fn the_queue_of_links_being_accepted_follows_the_open_files() {
        assert_eq!(accept_pending(0), ACCEPT_PENDING);
        assert_eq!(accept_pending(1024), ACCEPT_PENDING);
        assert_eq!(accept_pending(20_000), 20_000 - 1024);
        assert_eq!(accept_pending(1 << 20), (1 << 20) - 1024);
    }

    #[test]
    fn a_bad_endpoint_or_file_is_an_error_naming_it() {
        let net = NetConfig {
            config: Some("/no/such/zenoh.json5".into()),
            ..NetConfig::default()
        };
        let err = net.zenoh_config(true).unwrap_err().to_string();
        assert!(err.contains("/no/such/zenoh.json5"), "{err}");
    }
}
