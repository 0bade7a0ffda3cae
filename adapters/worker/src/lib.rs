//! The envhub worker: hosts one adapter's envs in its own process and serves them over shared
//! memory. Started by the hub (embedded in a client, or the `envhub serve` daemon); not meant
//! to be run by hand, except `envhub-worker describe` to see what it can host.
//!
//! Two binaries run it, built together. `envhub-worker`, the one the hub starts, links no
//! libmujoco, so it starts on any machine; when it finds libmujoco 3.17.0 (the `mujoco`
//! wheel's, see [`libmujoco`]) it replaces itself (`exec`, same pid) with
//! `envhub-worker-mujoco` beside it, which links the library and hosts every adapter.
//! Otherwise it hosts the rest itself and the MuJoCo adapters report what is missing. The
//! trade-off: a second binary, against a loader error that would take every native adapter
//! down with MuJoCo (a library a binary links must be found before `main` runs).
//!
//! rapier's adapter runs in a third binary, `envhub-worker-rapier`, which the other two hand
//! its jobs to ([`delegated`]): the binaries the demo runs build without rapier3d.

mod adapters;
pub mod delegated;
mod inproc;
pub mod libmujoco;
mod null_env;
mod serve;
mod unlinked;

pub use adapters::{native, set_adapters};
pub use unlinked::Unlinked;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "envhub-worker", version, about = "envhub worker process")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the adapters this binary hosts, with availability, as JSON (the test adapter
    /// `null` only with ENVHUB_TEST_ADAPTERS=1).
    Describe,
    /// Serve a job (JSON) over shared memory until closed or the owner exits.
    Serve {
        /// The job, as JSON.
        #[arg(long)]
        job: String,
    },
    /// Answer raw iceoryx2 pings (the benchmark's floor under a data-plane round trip) until
    /// none comes for a second.
    Pong {
        /// iceoryx2 namespace prefix.
        #[arg(long)]
        prefix: String,
        /// Base service name.
        #[arg(long)]
        service: String,
        /// Spin this long (µs) before blocking, as the client does.
        #[arg(long, default_value_t = 2000)]
        spin_us: u64,
    },
    /// Step a job's envs in this process, without IPC, on several threads; print steps/s.
    Inproc {
        /// The job, as JSON (`channel` is ignored).
        #[arg(long)]
        job: String,
        /// Threads (the envs are split among them like among workers).
        #[arg(long, default_value_t = 1)]
        threads: usize,
        /// Steps per env.
        #[arg(long, default_value_t = 1000)]
        steps: usize,
    },
}

/// Runs the worker's command line (`describe`, `serve`, ...) over the adapters set with
/// [`set_adapters`].
pub fn run() -> ExitCode {
    envhub_core::init_logging();
    let cli = Cli::parse();
    if let Command::Serve { job } | Command::Inproc { job, .. } = &cli.command
        && let Err(err) = hand_over(job)
    {
        let message = format!("{err:#}");
        // A served job's answer goes to the hub on stdout, as any job that cannot be served.
        if matches!(cli.command, Command::Serve { .. }) && serve::refuse(message.clone()).is_ok() {
            return ExitCode::SUCCESS;
        }
        eprintln!("envhub-worker: error: {message}");
        return ExitCode::from(2);
    }
    let result = match cli.command {
        Command::Describe => describe(),
        Command::Serve { job } => serve::run(&job),
        Command::Pong {
            prefix,
            service,
            spin_us,
        } => envhub_shm::pong(
            &prefix,
            &service,
            std::time::Duration::from_micros(spin_us),
            std::time::Duration::from_secs(1),
        )
        .map_err(anyhow::Error::from),
        Command::Inproc {
            job,
            threads,
            steps,
        } => inproc::run(&job, threads, steps),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("envhub-worker: error: {err:#}");
            ExitCode::from(2)
        }
    }
}

/// Hands `job` over to the binary that hosts its adapter, where another one does (see
/// [`delegated`]); returns when this binary serves it. A job it cannot read is left to the
/// command, which says what is wrong with it.
fn hand_over(job: &str) -> anyhow::Result<()> {
    #[derive(serde::Deserialize)]
    struct Adapter {
        adapter: String,
    }
    let Ok(Adapter { adapter }) = serde_json::from_str::<Adapter>(job) else {
        return Ok(());
    };
    delegated::hand_over(&adapter, adapters::hosts_itself(&adapter))
        .map_err(|e| anyhow::anyhow!("the worker for adapter `{adapter}`: {e}"))
}

fn describe() -> anyhow::Result<()> {
    let list: Vec<serde_json::Value> = adapters::listed()
        .iter()
        .map(|a| {
            let mut entry = serde_json::json!({
                "name": a.name(),
                "frameworks": a.frameworks(),
                "requires": a.requires(),
                "description": a.description(),
                "availability": a.availability(),
                "envs": a.list_envs(),
                "render_modes": a.render_modes(),
            });
            if adapters::is_testing(a.name()) {
                entry["testing"] = true.into();
            }
            entry
        })
        .collect();
    println!("{}", serde_json::to_string(&list)?);
    Ok(())
}
