//! Command-line parsing and dispatch. Each subcommand lives in its own file.

mod adapters;
mod bench;
mod env_cmd;
mod envs;
mod eval;
mod hubs;
mod lab;
mod match_cmd;
mod record;
mod run;
mod serve;
mod show;
mod table;

use clap::{Parser, Subcommand};
use envhub_hub::{Hub, Registry, Settings};
use std::path::PathBuf;
use std::process::ExitCode;

/// envhub — a zero-copy, shared-memory hub for robot-learning environments.
#[derive(Parser, Debug)]
#[command(name = "envhub", version, about, long_about = None)]
struct Cli {
    /// Registry file to use instead of the built-in catalog; repeat to combine files
    /// (`@default` is the built-in one). Overrides ENVHUB_REGISTRY and the config file.
    #[arg(long = "registry", value_name = "FILE", global = true)]
    registries: Vec<PathBuf>,

    /// Hub config file (default: ENVHUB_CONFIG, else ./envhub.yaml if present).
    #[arg(long, value_name = "FILE", global = true)]
    config: Option<PathBuf>,

    /// Zenoh endpoint of a hub (or router) to reach other hubs through, as
    /// `tcp/HOST:PORT`; repeat for several. Added to ENVHUB_CONNECT and the config's.
    #[arg(long, value_name = "ENDPOINT", global = true)]
    connect: Vec<String>,

    /// A Zenoh JSON5 config file (router, TLS, credentials) for reaching other hubs.
    #[arg(long, value_name = "FILE", global = true)]
    zenoh_config: Option<PathBuf>,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// List and filter the environments of the registry.
    Envs(envs::Args),
    /// Show one registry entry in full.
    Show(show::Args),
    /// Find the environment that best fits a task description.
    Match(match_cmd::Args),
    /// List the adapters (simulators) and whether they can run here.
    Adapters(adapters::Args),
    /// Run a random-policy rollout through the hub.
    Run(run::Args),
    /// Measure throughput through the hub against in-process stepping, and the round trip.
    Bench(bench::Args),
    /// Run the hub as a daemon that several client processes share (set ENVHUB_HUB to its
    /// socket in the clients), and that clients on other machines reach over Zenoh.
    Serve(serve::Args),
    /// List the live hubs on the network.
    Hubs(hubs::Args),
    /// Hubs and clients on several machines that trust one another: make a lab, add members.
    Lab(lab::Args),
    /// The Python environments suites run in (`python_envs:`): list, build, remove.
    Env(env_cmd::Args),
    /// Record episodes into a LeRobot dataset (v3: Parquet, MP4 per camera, meta/).
    Record(record::Args),
    /// Evaluate a policy on a benchmark's protocol (`envhub eval --list` names them).
    Eval(eval::Args),
}

/// What a subcommand reports besides its output: success, or "ran fine but found nothing".
pub(crate) enum Outcome {
    Done,
    NotFound,
}

/// Parses the command line, runs it, prints errors as `error: ...` with a `hint:` line.
pub fn run() -> ExitCode {
    let cli = Cli::parse();
    envhub_core::init_logging();
    match dispatch(cli) {
        Ok(Outcome::Done) => ExitCode::SUCCESS,
        Ok(Outcome::NotFound) => ExitCode::from(1),
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::from(2)
        }
    }
}

fn dispatch(cli: Cli) -> anyhow::Result<Outcome> {
    let settings = Settings::discover(cli.config.as_deref())?;
    let registry = || -> anyhow::Result<Registry> { Ok(settings.registry(&cli.registries)?) };
    let listen: &[String] = match &cli.command {
        Command::Serve(args) => args.listen(),
        _ => &[],
    };
    let net =
        settings
            .zenoh
            .clone()
            .with_overrides(&cli.connect, listen, cli.zenoh_config.as_deref());
    let hub = || -> anyhow::Result<Hub> {
        Ok(Hub::from_settings(&settings, &cli.registries)?.with_network(net.clone()))
    };
    match cli.command {
        Command::Envs(args) => match &args.hub {
            Some(name) => envs::run(&hub()?.remote_registry(name)?, &args),
            None => envs::run(&registry()?, &args),
        },
        Command::Hubs(args) => hubs::run(&hub()?, &args),
        Command::Lab(args) => lab::run(&args),
        Command::Env(args) => env_cmd::run(&registry()?, &args),
        Command::Show(args) => show::run(&registry()?, &args),
        Command::Match(args) => match_cmd::run(&registry()?, &args),
        Command::Adapters(args) => adapters::run(&hub()?, &args),
        Command::Run(args) => match &args.video {
            Some(path) => {
                hub()?; // applies the config's `python:` (the recorder's interpreter)
                record::video(
                    &cli.registries,
                    cli.config.as_deref(),
                    &args.id,
                    path,
                    args.video_steps,
                )
            }
            None => run::run(&hub()?, &args),
        },
        Command::Record(args) => {
            hub()?;
            record::run(&cli.registries, cli.config.as_deref(), &args)
        }
        Command::Eval(args) => {
            hub()?; // applies the config's `python:` (the evaluation's interpreter)
            eval::run(&cli.registries, cli.config.as_deref(), &args)
        }
        Command::Bench(args) => bench::run(&hub()?, &args),
        Command::Serve(args) => serve::run(Hub::new(registry()?), net, &args),
    }
}
