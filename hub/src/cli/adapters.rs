//! `envhub adapters`: which simulators this machine can run, and why not.

use super::{Outcome, table};
use envhub::Hub;
use envhub_core::Availability;

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
