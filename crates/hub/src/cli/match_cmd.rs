//! `envhub match`: the best environment for a task description.

use super::Outcome;
use envhub_hub::{MatchError, Registry, TaskSpec, match_task};

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// The task in plain language ("a quadruped runs forward").
    description: String,
    /// Robot type (`arm`, `quadruped`, ...).
    #[arg(long)]
    robot: Option<String>,
    /// Environment type (`tabletop`, `floor`, ...).
    #[arg(long = "env-type")]
    env_type: Option<String>,
    /// Restrict to a framework.
    #[arg(long)]
    framework: Option<String>,
    /// Robot model (`franka`, ...).
    #[arg(long)]
    model: Option<String>,
    /// Use this registry id (skips matching).
    #[arg(long)]
    id: Option<String>,
    /// Print `{"id", "score", "reason", "alternatives"}` as JSON.
    #[arg(long)]
    json: bool,
}

pub(crate) fn run(registry: &Registry, args: &Args) -> anyhow::Result<Outcome> {
    let spec = TaskSpec {
        task_description: args.description.clone(),
        robot_type: args.robot.clone(),
        environment_type: args.env_type.clone(),
        environment_id: args.id.clone(),
        framework: args.framework.clone(),
        robot_model: args.model.clone(),
    };
    let found = match match_task(&spec, registry) {
        Ok(found) => found,
        Err(MatchError::NoMatch { why, hint }) => {
            if args.json {
                println!("{}", serde_json::json!({ "id": null, "reason": why }));
            }
            eprintln!("no match: {why}\nhint: {hint}");
            return Ok(Outcome::NotFound);
        }
        Err(err) => return Err(err.into()),
    };
    if args.json {
        let out = serde_json::json!({
            "id": found.entry.id,
            "score": found.score,
            "reason": found.reason,
            "alternatives": found.alternatives,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(Outcome::Done);
    }
    let e = found.entry;
    println!(
        "{} ({}, {})  score {:.2}",
        e.id, e.env_id, e.framework, found.score
    );
    println!("  {}", e.description);
    println!("reason: {}", found.reason);
    if !found.alternatives.is_empty() {
        println!("alternatives:");
        for alt in &found.alternatives {
            let excluded = alt
                .excluded
                .as_ref()
                .map_or_else(String::new, |why| format!(" but {why}"));
            println!(
                "  {:<32} {:.2}  ({}){excluded}",
                alt.id,
                alt.score,
                alt.matched_tags.join(", ")
            );
        }
    }
    Ok(Outcome::Done)
}
