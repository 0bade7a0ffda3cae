//! `envhub envs`: list and filter the registry.

use super::{Outcome, table};
use envhub_hub::{Registry, SearchQuery};

/// Filters are case-insensitive substrings (`--framework gym` finds `gymnasium`).
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Framework (`gymnasium`, `maniskill`, `isaac_lab`, ...).
    #[arg(long)]
    framework: Option<String>,
    /// Robot type (`arm`, `quadruped`, `biped`, `dexterous_hand`, ...).
    #[arg(long)]
    robot: Option<String>,
    /// Robot model (`franka`, `ant`, ...).
    #[arg(long)]
    model: Option<String>,
    /// Environment type (`tabletop`, `floor`, `terrain`, ...).
    #[arg(long = "env-type")]
    env_type: Option<String>,
    /// Action type (`continuous` or `discrete`).
    #[arg(long = "action-type")]
    action_type: Option<String>,
    /// Task words, space- or comma-separated; results are sorted by how many match.
    #[arg(long, num_args = 1.., value_delimiter = ',')]
    tags: Vec<String>,
    /// Print a JSON array of entries.
    #[arg(long)]
    json: bool,
    /// List the catalog of this hub on the network instead of this machine's.
    #[arg(long, value_name = "NAME")]
    pub hub: Option<String>,
}

pub(crate) fn run(registry: &Registry, args: &Args) -> anyhow::Result<Outcome> {
    let tags: Vec<String> = args
        .tags
        .iter()
        .flat_map(|t| t.split_whitespace())
        .filter(|t| !t.is_empty())
        .map(str::to_string)
        .collect();
    let query = SearchQuery {
        robot_type: args.robot.clone(),
        env_type: args.env_type.clone(),
        framework: args.framework.clone(),
        robot_model: args.model.clone(),
        action_type: args.action_type.clone(),
        tags: tags.clone(),
    };
    let hits = registry.search(&query);
    if args.json {
        let entries: Vec<_> = hits.iter().map(|h| h.entry).collect();
        println!("{}", serde_json::to_string_pretty(&entries)?);
    }
    if hits.is_empty() {
        eprintln!("{}", explain_no_match(registry, args, &tags));
        return Ok(Outcome::NotFound);
    }
    if !args.json {
        // A column for the Python environment only where the catalog declares some.
        let with_envs = !registry.python_envs().all().is_empty();
        let rows: Vec<Vec<String>> = hits
            .iter()
            .map(|h| {
                let e = h.entry;
                let mut row = vec![
                    e.id.clone(),
                    e.env_id.clone(),
                    e.framework.clone(),
                    e.robot_type.clone(),
                    e.env_type.clone(),
                    table::truncate(&e.description, 60),
                ];
                if with_envs {
                    row.insert(5, super::env_cmd::env_column(registry, e));
                }
                row
            })
            .collect();
        let mut header = vec!["ID", "ENV_ID", "FRAMEWORK", "ROBOT", "TYPE", "DESCRIPTION"];
        if with_envs {
            header.insert(5, "PYTHON_ENV");
        }
        print!("{}", table::render(&header, &rows));
        println!("{} of {} environments", hits.len(), registry.len());
    }
    Ok(Outcome::Done)
}

/// Names the filters that were given and, for each, the values the registry has.
fn explain_no_match(registry: &Registry, args: &Args, tags: &[String]) -> String {
    let given: Vec<(&str, &str, &Option<String>)> = vec![
        ("framework", "framework", &args.framework),
        ("robot", "robot_type", &args.robot),
        ("model", "robot_model", &args.model),
        ("env-type", "env_type", &args.env_type),
        ("action-type", "action_type", &args.action_type),
    ];
    let mut filters: Vec<String> = given
        .iter()
        .filter_map(|(flag, _, v)| v.as_ref().map(|v| format!("--{flag} `{v}`")))
        .collect();
    if !tags.is_empty() {
        filters.push(format!("--tags `{}`", tags.join(" ")));
    }
    let mut msg = format!("no environments match {}", filters.join(" "));
    for (flag, field, value) in given {
        if value.is_some() {
            msg.push_str(&format!(
                "\nhint: --{flag} values: {}",
                registry.distinct(field).join(", ")
            ));
        }
    }
    if !tags.is_empty() {
        let mut all: Vec<String> = registry
            .entries()
            .iter()
            .flat_map(|e| e.task_tags.iter().cloned())
            .collect();
        all.sort();
        all.dedup();
        msg.push_str(&format!("\nhint: task tags in use: {}", all.join(", ")));
    }
    msg
}
