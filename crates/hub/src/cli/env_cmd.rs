//! `envhub env list|lock|sync|run|remove|prune`: the Python environments suites run in.

use super::{Outcome, table};
use anyhow::Context;
use envhub_hub::Registry;
use envhub_hub::provision;
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
    /// Resolve the named environments (or all) with uv's resolver into the lock file beside
    /// the registry file that declares each (`<registry>.lock.yaml`), for this platform and
    /// those the lock already has (or those `--platform` names). Commit the lock file.
    Lock {
        /// Names (`python_envs:` of the registry); none: every one.
        names: Vec<String>,
        /// Resolve for exactly these platforms (uv's names: `x86_64-unknown-linux-gnu`,
        /// `aarch64-unknown-linux-gnu`, `aarch64-apple-darwin`); repeatable.
        #[arg(long = "platform", value_name = "PLATFORM")]
        platforms: Vec<String>,
    },
    /// Build (if not ready) the named environments of the catalog, or all of them: exactly
    /// their lock's pins for this platform where their registry file has a lock file.
    Sync {
        /// Names (`python_envs:` of the registry); none: every one.
        names: Vec<String>,
    },
    /// Run a program in a catalog environment (built first if not ready), as its workers
    /// run: its interpreter and variables, importing this install's `envhub`, holding the
    /// environment so it is not removed under it. `envhub env run metaworld -- -m
    /// my_eval --tasks 10`, `envhub env run libero -- script.py`.
    Run {
        /// The environment's name (`python_envs:` of the registry).
        name: String,
        /// The interpreter's arguments (after `--`).
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<std::ffi::OsString>,
    },
    /// Delete the built environments of these names (every version of each); refused while
    /// running sessions' workers use one, naming their pids.
    Remove {
        /// Names, or folder names as `envhub env list` shows them.
        #[arg(required = true)]
        names: Vec<String>,
        /// Remove it even while sessions use it (their workers then fail, saying so).
        #[arg(long)]
        force: bool,
    },
    /// Delete the built environments that the rules select (any of them); never one that
    /// running sessions use.
    #[command(arg_required_else_help = true)]
    Prune {
        /// Those unused (no session, no build) for this many days.
        #[arg(long, value_name = "DAYS")]
        unused_days: Option<f64>,
        /// Those the catalog's registries do not name (old keys, other registries' ones).
        #[arg(long)]
        unnamed: bool,
        /// Then the least recently used, until the cache uses at most this much disk
        /// (`500M`, `20G`; files hard-linked several times counted once).
        #[arg(long, value_name = "SIZE", value_parser = parse_size)]
        max_size: Option<u64>,
        /// Say what would be removed, and remove nothing.
        #[arg(long)]
        dry_run: bool,
    },
}

/// `500M`, `20G`, `1.5T`, `1000` (bytes; K, M, G, T are powers of 1000).
fn parse_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let (number, scale) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let scale = match c.to_ascii_uppercase() {
                'K' => 1e3,
                'M' => 1e6,
                'G' => 1e9,
                'T' => 1e12,
                _ => return Err(format!("`{text}`: unknown unit `{c}`; use K, M, G or T")),
            };
            (&t[..i], scale)
        }
        _ => (t, 1.0),
    };
    match number.trim().parse::<f64>() {
        Ok(n) if n.is_finite() && n >= 0.0 => Ok((n * scale) as u64),
        _ => Err(format!("`{text}` is not a size such as `500M` or `20G`")),
    }
}

pub(crate) fn run(registry: &Registry, args: &Args) -> anyhow::Result<Outcome> {
    let store = provision::store().map_err(anyhow::Error::msg)?;
    match &args.command {
        Command::List { json } => list(registry, store, *json),
        Command::Lock { names, platforms } => lock(registry, store, names, platforms),
        Command::Sync { names } => sync(registry, store, names),
        Command::Run { name, args } => run_in(registry, name, args),
        Command::Remove { names, force } => {
            for name in names {
                for dir in store.remove(name, *force)? {
                    println!("removed {}", dir.display());
                }
            }
            Ok(Outcome::Done)
        }
        Command::Prune {
            unused_days,
            unnamed,
            max_size,
            dry_run,
        } => prune(registry, store, *unused_days, *unnamed, *max_size, *dry_run),
    }
}

/// Replaces this process with the program (so signals, pipes and the exit status are the
/// program's own), holding the environment across the `exec`.
fn run_in(registry: &Registry, name: &str, args: &[std::ffi::OsString]) -> anyhow::Result<Outcome> {
    use std::os::unix::process::CommandExt;
    let (mut program, env) =
        provision::program_in(registry, name, args).map_err(anyhow::Error::msg)?;
    let _held = match &env.hold {
        Some(hold) => Some(envhub_pyenv::shared_across_exec(hold).with_context(|| {
            format!(
                "cannot hold python env `{name}` (`{}`): it was removed\nhint: `envhub env sync {name}` builds it again",
                hold.display()
            )
        })?),
        None => None,
    };
    let error = program.exec();
    anyhow::bail!(
        "cannot run `{}` of python env `{name}`: {error}",
        env.interpreter.display()
    )
}

fn prune(
    registry: &Registry,
    store: &envhub_pyenv::Store,
    unused_days: Option<f64>,
    unnamed: bool,
    max_size: Option<u64>,
    dry_run: bool,
) -> anyhow::Result<Outcome> {
    let unused_for = unused_days
        .map(|d| {
            anyhow::ensure!(
                d.is_finite() && d >= 0.0,
                "`--unused-days {d}` is not a number of days"
            );
            Ok(std::time::Duration::from_secs_f64(d * 86_400.0))
        })
        .transpose()?;
    let named = unnamed.then(|| {
        registry
            .python_envs()
            .all()
            .iter()
            .filter_map(|(name, spec)| store.plan(name, spec).ok().map(|p| p.dir))
            .collect()
    });
    let rule = envhub_pyenv::PruneRule {
        unused_for,
        named,
        max_bytes: max_size,
    };
    let pruned = store.prune(&rule, dry_run)?;
    let verb = if dry_run { "would remove" } else { "removed" };
    for (dir, bytes) in &pruned.removed {
        println!("{verb} {} ({})", dir.display(), megabytes(*bytes));
    }
    for (dir, pids) in &pruned.in_use {
        let pids: Vec<String> = pids.iter().map(u32::to_string).collect();
        println!(
            "kept {} (in use by pid {})",
            dir.display(),
            if pids.is_empty() {
                "unknown".into()
            } else {
                pids.join(", ")
            }
        );
    }
    println!(
        "{} environment(s) {verb}; the cache's environments use {}",
        pruned.removed.len(),
        megabytes(pruned.left_bytes)
    );
    Ok(Outcome::Done)
}

fn megabytes(bytes: u64) -> String {
    format!("{:.0} MB", bytes as f64 / 1e6)
}

/// The named environments of the catalog with their declarations (all of them when none is
/// named); `None`, said on stderr, when the catalog declares none.
fn chosen<'a>(
    registry: &'a Registry,
    names: &'a [String],
) -> anyhow::Result<Option<Vec<(&'a String, &'a envhub_pyenv::PythonEnvSpec)>>> {
    let all = registry.python_envs().all();
    if all.is_empty() {
        eprintln!(
            "the catalog declares no Python environments (`python_envs:` in a registry file)"
        );
        return Ok(None);
    }
    if names.is_empty() {
        return Ok(Some(all.iter().collect()));
    }
    let chosen = names
        .iter()
        .map(|name| {
            Ok((
                name,
                provision::declared(registry, name).map_err(anyhow::Error::msg)?,
            ))
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(Some(chosen))
}

fn lock(
    registry: &Registry,
    store: &envhub_pyenv::Store,
    names: &[String],
    platforms: &[String],
) -> anyhow::Result<Outcome> {
    use envhub_pyenv::LockFile;
    use std::collections::BTreeMap;
    use std::path::PathBuf;
    let envs = registry.python_envs();
    let Some(chosen) = chosen(registry, names)? else {
        return Ok(Outcome::NotFound);
    };
    let mut files: BTreeMap<PathBuf, LockFile> = BTreeMap::new();
    let mut failed = Vec::new();
    for (name, spec) in chosen {
        let path = envs.lock_file(name).with_context(|| {
            format!(
                "python env `{name}` is declared by the built-in catalog, whose lock file lives in an envhub checkout\nhint: run `envhub env lock` from the checkout's root (the folder holding configs/env_registry.yaml), then rebuild envhub"
            )
        })?;
        let file = files.entry(path.to_path_buf()).or_insert_with(|| {
            std::fs::read_to_string(path)
                .ok()
                .and_then(|text| LockFile::parse(&text).ok())
                .unwrap_or(LockFile {
                    version: envhub_pyenv::LOCK_VERSION,
                    ..Default::default()
                })
        });
        let wanted: Vec<String> = if platforms.is_empty() {
            let mut wanted = vec![envhub_pyenv::platform()];
            if let Some(old) = file.python_envs.get(name) {
                wanted.extend(old.platforms.keys().cloned());
            }
            wanted.sort();
            wanted.dedup();
            wanted
        } else {
            platforms.to_vec()
        };
        let start = std::time::Instant::now();
        match store.lock(name, spec, &wanted) {
            Ok(lock) => {
                let counts: Vec<String> = lock
                    .platforms
                    .iter()
                    .map(|(p, pins)| format!("{p}: {} packages", pins.len()))
                    .collect();
                println!(
                    "{name}: locked for Python {} in {:.1} s ({})",
                    lock.python,
                    start.elapsed().as_secs_f64(),
                    counts.join(", ")
                );
                file.python_envs.insert(name.clone(), lock);
            }
            Err(e) => {
                eprintln!("error: {e:#}");
                failed.push(name.clone());
            }
        }
    }
    for (path, file) in &mut files {
        // What the registry file no longer declares leaves its lock.
        file.python_envs
            .retain(|n, _| envs.lock_file(n) == Some(path.as_path()));
        let registry_name = path
            .file_name()
            .map(|n| n.to_string_lossy().replace(".lock.yaml", ".yaml"))
            .unwrap_or_default();
        let tmp = path.with_extension(format!("tmp-{}", std::process::id()));
        std::fs::write(&tmp, file.render(&registry_name))
            .and_then(|()| std::fs::rename(&tmp, path))
            .with_context(|| format!("cannot write the lock file `{}`", path.display()))?;
        println!("wrote {}", path.display());
    }
    anyhow::ensure!(failed.is_empty(), "failed to lock: {}", failed.join(", "));
    Ok(Outcome::Done)
}

fn sync(
    registry: &Registry,
    store: &envhub_pyenv::Store,
    names: &[String],
) -> anyhow::Result<Outcome> {
    let Some(chosen) = chosen(registry, names)? else {
        return Ok(Outcome::NotFound);
    };
    let mut failed = Vec::new();
    for (name, spec) in chosen {
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
    /// `locked`, `unlocked` (its registry file has no lock file), or why its lock does not
    /// fit: `stale`, `not in lock`, `no pins for <platform>`, `locked for Python <version>`.
    lock: String,
    /// Why it cannot be built as declared (a lock that does not fit), if so.
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    /// What they resolved to when it was built (`name==version`; empty: not built, or
    /// built by an envhub that did not record it).
    resolved: Vec<String>,
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
                    lock: store.lock_state(name, spec),
                    error: None,
                    resolved: found
                        .and_then(|s| s.manifest.as_ref().map(|m| m.resolved.clone()))
                        .unwrap_or_default(),
                });
            }
            Err(e @ envhub_pyenv::PyEnvError::Lock { .. }) => rows.push(Row {
                name: name.clone(),
                folder: String::new(),
                ready: false,
                in_catalog: true,
                python: spec.python.clone().unwrap_or_else(|| "(hub's)".into()),
                size_bytes: None,
                last_use_unix: None,
                requirements: spec.requirements.clone(),
                lock: store.lock_state(name, spec),
                error: Some(e.to_string()),
                resolved: Vec::new(),
            }),
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
            lock: match s.manifest.as_ref() {
                Some(m) if !m.locked.is_empty() => "locked".into(),
                Some(_) => "unlocked".into(),
                None => "-".into(),
            },
            error: None,
            resolved: s
                .manifest
                .as_ref()
                .map(|m| m.resolved.clone())
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
                r.lock.clone(),
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
                "LOCK",
                "SIZE",
                "LAST USE",
                "REQUIREMENTS"
            ],
            &cells
        )
    );
    for r in rows.iter().filter(|r| r.error.is_some()) {
        eprintln!("warning: {}", r.error.as_deref().unwrap_or_default());
    }
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
pub(crate) fn env_column(registry: &Registry, entry: &envhub_hub::EnvEntry) -> String {
    let Some((name, spec)) = provision::env_of(registry, entry) else {
        return String::new();
    };
    match provision::is_ready(name, spec) {
        Ok(true) => format!("{name} (ready)"),
        _ => format!("{name} (not built)"),
    }
}
