//! `envhub env list|sync|remove`: the Python environments suites run in.

use super::{Outcome, table};
use anyhow::Context;
use envhub::Registry;
use envhub::provision;
use std::time::SystemTime;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// The catalog's Python environments and those built in the cache folder: key, whether
    /// ready, Python version, size, last use, requirements.
    List {
        /// Print a JSON array.
        #[arg(long)]
        json: bool,
    },
    /// Build (if not ready) the named environments of the catalog, or all of them.
    Sync {
        /// Names (`python_envs:` of the registry); none: every one.
        names: Vec<String>,
    },
    /// Delete the built environments of these names (every version of each).
    Remove {
        /// Names, or folder names as `envhub env list` shows them.
        #[arg(required = true)]
        names: Vec<String>,
    },
}

pub(crate) fn run(registry: &Registry, args: &Args) -> anyhow::Result<Outcome> {
    let store = provision::store().map_err(anyhow::Error::msg)?;
    match &args.command {
        Command::List { json } => list(registry, store, *json),
        Command::Sync { names } => sync(registry, store, names),
        Command::Remove { names } => {
            for name in names {
                for dir in store.remove(name)? {
                    println!("removed {}", dir.display());
                }
            }
            Ok(Outcome::Done)
        }
    }
}

fn sync(
    registry: &Registry,
    store: &envhub_pyenv::Store,
    names: &[String],
) -> anyhow::Result<Outcome> {
    let all = registry.python_envs().all();
    if all.is_empty() {
        eprintln!(
            "the catalog declares no Python environments (`python_envs:` in a registry file)"
        );
        return Ok(Outcome::NotFound);
    }
    let chosen: Vec<&String> = if names.is_empty() {
        all.keys().collect()
    } else {
        names.iter().collect()
    };
    let mut failed = Vec::new();
    for name in chosen {
        let spec = all.get(name).with_context(|| {
            let known: Vec<&str> = all.keys().map(String::as_str).collect();
            format!("no python env `{name}` in the catalog (defined: {})\nhint: `envhub env list` shows them", known.join(", "))
        })?;
        let start = std::time::Instant::now();
        match store.ensure(name, spec) {
            Ok(env) => println!(
                "{name}: {} in {:.1} s ({})",
                if env.built { "built" } else { "ready" },
                start.elapsed().as_secs_f64(),
                env.dir.display()
            ),
            // One suite's failure does not stop the others.
            Err(e) => {
                eprintln!("error: {e:#}");
                failed.push(name.clone());
            }
        }
    }
    anyhow::ensure!(failed.is_empty(), "failed to build: {}", failed.join(", "));
    Ok(Outcome::Done)
}

#[derive(serde::Serialize)]
struct Row {
    name: String,
    folder: String,
    ready: bool,
    in_catalog: bool,
    python: String,
    size_bytes: Option<u64>,
    last_use_unix: Option<u64>,
    requirements: Vec<String>,
}

fn list(registry: &Registry, store: &envhub_pyenv::Store, json: bool) -> anyhow::Result<Outcome> {
    let stored = store.list();
    let mut rows = Vec::new();
    let mut shown = Vec::new();
    for (name, spec) in registry.python_envs().all() {
        match store.plan(name, spec) {
            Ok(plan) => {
                let found = stored.iter().find(|s| s.dir == plan.dir);
                shown.push(plan.dir.clone());
                let ready = store.ready(&plan).is_some();
                rows.push(Row {
                    name: name.clone(),
                    folder: plan
                        .dir
                        .file_name()
                        .map(|f| f.to_string_lossy().into_owned())
                        .unwrap_or_default(),
                    ready,
                    in_catalog: true,
                    python: found
                        .and_then(|s| s.manifest.as_ref().map(|m| m.python_version.clone()))
                        .unwrap_or_else(|| spec.python.clone().unwrap_or_else(|| "(hub's)".into())),
                    size_bytes: found.map(|s| s.size_bytes),
                    last_use_unix: found.and_then(|s| unix(s.last_use)),
                    requirements: plan.requirements,
                });
            }
            Err(e) => eprintln!("warning: {e}"),
        }
    }
    for s in stored.iter().filter(|s| !shown.contains(&s.dir)) {
        rows.push(Row {
            name: s
                .manifest
                .as_ref()
                .map_or_else(|| "(incomplete build)".into(), |m| m.name.clone()),
            folder: s.dir_name.clone(),
            ready: s.manifest.is_some(),
            in_catalog: false,
            python: s
                .manifest
                .as_ref()
                .map(|m| m.python_version.clone())
                .unwrap_or_default(),
            size_bytes: Some(s.size_bytes),
            last_use_unix: unix(s.last_use),
            requirements: s
                .manifest
                .as_ref()
                .map(|m| m.requirements.clone())
                .unwrap_or_default(),
        });
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(Outcome::Done);
    }
    let now = unix(Some(SystemTime::now())).unwrap_or(0);
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.name.clone(),
                r.folder.rsplit('-').next().unwrap_or("").to_string(),
                match (r.ready, r.in_catalog) {
                    (true, true) => "yes".into(),
                    (false, true) => "no".into(),
                    (true, false) => "yes (not in catalog)".into(),
                    (false, false) => "no (interrupted)".into(),
                },
                r.python.clone(),
                r.size_bytes
                    .map_or("-".into(), |b| format!("{:.0} MB", b as f64 / 1e6)),
                r.last_use_unix
                    .map_or("-".into(), |t| ago(now.saturating_sub(t))),
                table::truncate(&r.requirements.join(" "), 70),
            ]
        })
        .collect();
    print!(
        "{}",
        table::render(
            &[
                "NAME",
                "KEY",
                "READY",
                "PYTHON",
                "SIZE",
                "LAST USE",
                "REQUIREMENTS"
            ],
            &cells
        )
    );
    println!("cache: {}", store.root().display());
    Ok(Outcome::Done)
}

fn unix(t: Option<SystemTime>) -> Option<u64> {
    t?.duration_since(SystemTime::UNIX_EPOCH)
        .ok()
        .map(|d| d.as_secs())
}

fn ago(seconds: u64) -> String {
    match seconds {
        s if s < 120 => format!("{s} s ago"),
        s if s < 7200 => format!("{} min ago", s / 60),
        s if s < 172_800 => format!("{} h ago", s / 3600),
        s => format!("{} days ago", s / 86_400),
    }
}

/// The python env column of `envhub envs`: `name (ready)`, else `name (not built)` (also
/// where that cannot be checked: no uv), empty for entries in the hub's interpreter.
pub(crate) fn env_column(registry: &Registry, entry: &envhub::EnvEntry) -> String {
    let Some((name, spec)) = provision::env_of(registry, entry) else {
        return String::new();
    };
    match provision::is_ready(name, spec) {
        Ok(true) => format!("{name} (ready)"),
        _ => format!("{name} (not built)"),
    }
}
