//! `envhub serve`: the hub as a daemon, on this machine's socket and on the network.

use super::Outcome;
use envhub_hub::{Hub, NetConfig, ServePolicy};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Control socket (default: envhub.sock in $XDG_RUNTIME_DIR/envhub, else in
    /// ~/.cache/envhub/run; a folder only this user owns, checked before use).
    #[arg(long)]
    socket: Option<PathBuf>,
    /// Name of this hub on the network (default: the host name).
    #[arg(long)]
    name: Option<String>,
    /// Zenoh endpoint to listen on (`tcp/127.0.0.1:7447`); repeat for several. Default:
    /// loopback on a free port (this user's clients find it in the folder of local hubs)
    /// unless the Zenoh config gives credentials. On loopback without credentials the hub
    /// admits only this user's processes; an address beyond loopback without credentials
    /// needs `--insecure-listen`.
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Listen (or connect) beyond loopback without credentials, or share a loopback
    /// `--listen` with every user of this machine: anyone who reaches the hub can run envs
    /// on it. Prints a warning.
    #[arg(long)]
    insecure_listen: bool,
    /// Send and answer multicast scouts on the LAN without credentials (with
    /// `--insecure-listen` and a `--listen` beyond loopback), so clients that scout
    /// (`ENVHUB_MULTICAST=1`) find this hub. Off otherwise, `--insecure-listen` included; the
    /// hub never connects to what scouting names.
    #[arg(long)]
    multicast_scouting: bool,
    /// Stay off the network: serve only this machine's clients on the Unix socket.
    #[arg(long)]
    local_only: bool,
    /// Envs this hub runs for remote clients at once, over all their sessions (0: no limit).
    #[arg(long, value_name = "N", default_value_t = envhub_hub::DEFAULT_MAX_ENVS)]
    max_envs: usize,
    /// Worker processes this hub runs for remote clients at once (0: no limit). Default: 4
    /// per core.
    #[arg(long, value_name = "N")]
    max_workers: Option<usize>,
    /// Envs one client (one identity key) holds here while another waits for room: past
    /// it a session is only lent, and closed when another client asks for the room (0: no
    /// share). Default: half of `--max-envs`.
    #[arg(long, value_name = "N")]
    max_envs_per_client: Option<usize>,
    /// Worker processes one client (one identity key) holds here while another waits for
    /// room, as `--max-envs-per-client` (0: no share). Default: half of `--max-workers`.
    #[arg(long, value_name = "N")]
    max_workers_per_client: Option<usize>,
    /// Sessions one client may hold here at once (0: no limit).
    #[arg(long, value_name = "N", default_value_t = envhub_hub::DEFAULT_MAX_SESSIONS_PER_CLIENT)]
    max_sessions_per_client: usize,
    /// The longest step timeout a remote client may ask for, in seconds.
    #[arg(long, value_name = "SECS", default_value_t = envhub_hub::DEFAULT_MAX_STEP_TIMEOUT.as_secs())]
    max_step_timeout: u64,
    /// Close a remote session whose client sent nothing for this long, in seconds (0: never).
    #[arg(long, value_name = "SECS", default_value_t = envhub_hub::DEFAULT_IDLE_TIMEOUT.as_secs())]
    idle_timeout: u64,
    /// The largest message the hub accepts from the network, in bytes.
    #[arg(long, value_name = "BYTES", default_value_t = envhub_hub::DEFAULT_MAX_REQUEST_BYTES)]
    max_request_bytes: usize,
    /// Let remote clients name files on this machine (`asset_path`, `xml_file`, ...). Off by
    /// default: remote clients run this hub's registry entries as they are.
    #[arg(long)]
    allow_remote_files: bool,
    /// Build the Python environment a suite needs (`python_envs:`) when a remote client's
    /// session needs one that is not provisioned yet. Off by default: such a session is
    /// refused, naming the environment (`envhub env sync` builds it here beforehand).
    #[arg(long)]
    allow_provision: bool,
}

impl Args {
    pub(crate) fn listen(&self) -> &[String] {
        &self.listen
    }
}

pub(crate) fn run(hub: Hub, net: NetConfig, args: &Args) -> anyhow::Result<Outcome> {
    let socket = match &args.socket {
        Some(socket) => socket.clone(),
        None => envhub_hub::default_socket()?,
    };
    let hub = Arc::new(hub);
    let node = if args.local_only {
        None
    } else {
        let name = args.name.clone().unwrap_or_else(envhub_hub::host_name);
        let limit = |n: usize| (n > 0).then_some(n);
        let defaults = ServePolicy::default();
        let max_envs = limit(args.max_envs);
        let max_workers = args.max_workers.map_or(defaults.max_workers, limit);
        let policy = ServePolicy {
            max_envs,
            max_workers,
            max_envs_per_client: args
                .max_envs_per_client
                .map_or(envhub_hub::client_share(max_envs), limit),
            max_workers_per_client: args
                .max_workers_per_client
                .map_or(envhub_hub::client_share(max_workers), limit),
            max_sessions_per_client: limit(args.max_sessions_per_client),
            max_step_timeout: Duration::from_secs(args.max_step_timeout),
            idle_timeout: (args.idle_timeout > 0).then(|| Duration::from_secs(args.idle_timeout)),
            max_request_bytes: args.max_request_bytes,
            allow_remote_files: args.allow_remote_files,
            allow_provision: args.allow_provision,
            insecure_listen: args.insecure_listen,
            multicast_scouting: args.multicast_scouting,
        };
        let node = envhub_hub::join(hub.clone(), &name, &net, policy)?;
        if let Some(notice) = node.exposure_notice() {
            eprintln!("{notice}");
        }
        Some(node)
    };
    envhub_hub::serve(&socket, hub, || {
        // For scripts and tests waiting for the daemon to be up. A closed stdout must not
        // take the daemon down, so write errors are ignored.
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        let _ = writeln!(
            out,
            "envhub hub listening on {}\nclients: export ENVHUB_HUB={}",
            socket.display(),
            socket.display()
        );
        if let Some(node) = &node {
            let _ = writeln!(out, "on the network as hub `{}`", node.name());
        }
        let _ = out.flush();
    })?;
    Ok(Outcome::Done)
}
