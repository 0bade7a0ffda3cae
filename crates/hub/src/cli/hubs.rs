//! `envhub hubs`: the live hubs on the network.

use super::{Outcome, table};
use envhub_hub::Hub;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Print JSON (one object per hub).
    #[arg(long)]
    json: bool,
}

pub(crate) fn run(hub: &Hub, args: &Args) -> anyhow::Result<Outcome> {
    let hubs = hub.hubs()?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&hubs)?);
    } else if hubs.is_empty() {
        eprintln!(
            "no live hubs found\nhint: start one with `envhub serve` on each machine; without multicast, pass `--connect tcp/HOST:PORT` (or set ENVHUB_CONNECT)"
        );
    } else {
        let rows: Vec<Vec<String>> = hubs
            .iter()
            .map(|h| {
                vec![
                    h.name.clone(),
                    h.host.clone(),
                    h.cores.to_string(),
                    h.version.clone(),
                    h.envs.to_string(),
                    h.workers.to_string(),
                    format!("{:.2}", h.load),
                    h.catalog.to_string(),
                    h.adapters.join(","),
                ]
            })
            .collect();
        print!(
            "{}",
            table::render(
                &[
                    "NAME", "HOST", "CORES", "VERSION", "ENVS", "WORKERS", "LOAD", "CATALOG",
                    "ADAPTERS",
                ],
                &rows
            )
        );
    }
    Ok(if hubs.is_empty() {
        Outcome::NotFound
    } else {
        Outcome::Done
    })
}
