//! `envhub adapters`: which simulators this machine can run, and why not.

use super::{Outcome, table};
use envhub_core::Availability;
use envhub_hub::Hub;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Include unavailable adapters, with the reason and the fix.
    #[arg(long)]
    all: bool,
    /// Print a JSON array.
    #[arg(long)]
    json: bool,
    /// Ask this hub on the network instead of this machine.
    #[arg(long, value_name = "NAME")]
    hub: Option<String>,
}

pub(crate) fn run(hub: &Hub, args: &Args) -> anyhow::Result<Outcome> {
    let all = match &args.hub {
        Some(name) => hub.remote_adapters(name)?,
        None => hub.adapters()?,
    };
    let adapters: Vec<_> = all
        .iter()
        .filter(|a| args.all || a.availability.is_available())
        .collect();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&adapters)?);
        return Ok(Outcome::Done);
    }
    let rows: Vec<Vec<String>> = adapters
        .iter()
        .map(|a| {
            let (status, note) = match &a.availability {
                Availability::Available => (
                    "yes".to_string(),
                    if a.envs.is_empty() {
                        a.description.clone()
                    } else {
                        a.envs.join(", ")
                    },
                ),
                Availability::Unavailable { reason, hint } => {
                    ("no".to_string(), format!("{reason} (fix: {hint})"))
                }
            };
            // Suites in their own Python environment run there, whatever the hub's
            // interpreter lacks: say which, and whether it is built.
            let envs = python_envs_of(hub, a);
            let (status, note) = if envs.is_empty() {
                (status, note)
            } else {
                (
                    format!("{status}; in env"),
                    format!("runs in python env {}", envs.join(", ")),
                )
            };
            vec![a.name.clone(), status, a.frameworks.join(", "), note]
        })
        .collect();
    print!(
        "{}",
        table::render(
            &["ADAPTER", "AVAILABLE", "FRAMEWORKS", "ENVS / WHY NOT"],
            &rows
        )
    );
    Ok(Outcome::Done)
}

/// The Python environments (with their state) that the registry's entries of `adapter`'s
/// frameworks run in: `` `metaworld` (ready) ``.
fn python_envs_of(hub: &Hub, adapter: &envhub_hub::AdapterInfo) -> Vec<String> {
    let registry = hub.registry();
    if registry.python_envs().all().is_empty() {
        return Vec::new();
    }
    let mut names: Vec<(String, String)> = Vec::new();
    for entry in registry.entries() {
        let framework =
            envhub_core::canonical_framework(&entry.framework).unwrap_or(&entry.framework);
        if !adapter.frameworks.iter().any(|f| f == framework) {
            continue;
        }
        if let Some((name, spec)) = envhub_hub::provision::env_of(registry, entry)
            && !names.iter().any(|(n, _)| n == name)
        {
            let state = match envhub_hub::provision::is_ready(name, spec) {
                Ok(true) => "ready",
                Ok(false) => "not built: `envhub env sync`",
                Err(_) => "cannot check",
            };
            names.push((name.to_string(), state.to_string()));
        }
    }
    names
        .into_iter()
        .map(|(n, s)| format!("`{n}` ({s})"))
        .collect()
}
