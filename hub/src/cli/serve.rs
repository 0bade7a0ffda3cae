//! `envhub serve`: the hub as a daemon.

use super::Outcome;
use envhub::Hub;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Control socket (default: $XDG_RUNTIME_DIR/envhub.sock, else /tmp/envhub-<uid>.sock).
    #[arg(long)]
    socket: Option<PathBuf>,
}

pub(crate) fn run(hub: Hub, args: &Args) -> anyhow::Result<Outcome> {
    let socket = args.socket.clone().unwrap_or_else(envhub::default_socket);
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
        let _ = out.flush();
    })?;
    Ok(Outcome::Done)
}
