//! `envhub serve`: the hub as a daemon, on this machine's socket and on the network.

use super::Outcome;
use envhub::{Hub, NetConfig, ServePolicy};
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Control socket (default: $XDG_RUNTIME_DIR/envhub.sock, else /tmp/envhub-<uid>/envhub.sock).
    #[arg(long)]
    socket: Option<PathBuf>,
    /// Name of this hub on the network (default: the host name).
    #[arg(long)]
    name: Option<String>,
    /// Zenoh endpoint to listen on (`tcp/0.0.0.0:7447`); repeat for several. Default: Zenoh's
    /// (every interface, a free port), found by multicast scouting.
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Stay off the network: serve only this machine's clients on the Unix socket.
    #[arg(long)]
    local_only: bool,
    /// Envs this hub runs for remote clients at once, over all their sessions.
    #[arg(long)]
    max_envs: Option<usize>,
    /// Worker processes this hub runs for remote clients at once.
    #[arg(long)]
    max_workers: Option<usize>,
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
    let socket = args.socket.clone().unwrap_or_else(envhub::default_socket);
    let hub = Arc::new(hub);
    let node = if args.local_only {
        None
    } else {
        let name = args.name.clone().unwrap_or_else(envhub::host_name);
        let policy = ServePolicy {
            max_envs: args.max_envs,
            max_workers: args.max_workers,
            allow_remote_files: args.allow_remote_files,
            allow_provision: args.allow_provision,
        };
        Some(envhub::join(hub.clone(), &name, &net, policy)?)
    };
    envhub::serve(&socket, hub, || {
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
