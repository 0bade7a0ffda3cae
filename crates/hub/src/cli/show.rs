//! `envhub show`: one entry in full.

use super::Outcome;
use envhub_hub::Registry;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Registry id (`mujoco-ant`).
    id: String,
    /// Print the entry as a JSON object.
    #[arg(long)]
    json: bool,
}

pub(crate) fn run(registry: &Registry, args: &Args) -> anyhow::Result<Outcome> {
    let entry = registry.get(&args.id)?;
    let value = serde_json::to_value(entry)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&value)?);
        return Ok(Outcome::Done);
    }
    let fields = value.as_object().expect("an entry serializes to an object");
    let width = fields.keys().map(String::len).max().unwrap_or(0);
    for (key, v) in fields {
        let shown = match v {
            serde_json::Value::String(s) => s.clone(),
            serde_json::Value::Array(items) => items
                .iter()
                .map(|i| i.as_str().map_or_else(|| i.to_string(), str::to_string))
                .collect::<Vec<_>>()
                .join(", "),
            other => other.to_string(),
        };
        println!("{key:<width$}  {shown}");
    }
    Ok(Outcome::Done)
}
