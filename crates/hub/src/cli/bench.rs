//! `envhub bench`: throughput through the hub next to the same envs stepped in-process, and
//! the data plane's round trip with an env that does no work — all in one run.

use super::Outcome;
use envhub_core::EnvConfig;
use envhub_hub::{Hub, VecEnv};
use envhub_shm::{ChannelName, SlotsName, WorkerJob};
use rand::SeedableRng;
use std::time::{Duration, Instant};

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Registry id (`gym-cartpole`).
    id: String,
    /// Envs in the batch.
    #[arg(long, default_value_t = 8)]
    num_envs: usize,
    /// Worker processes (and in-process threads).
    #[arg(long, default_value_t = 1)]
    workers: usize,
    /// Seconds to measure each throughput for.
    #[arg(long, default_value_t = 2.0)]
    seconds: f64,
    /// Round trips to time with the no-op env.
    #[arg(long, default_value_t = 20_000)]
    round_trips: usize,
    /// Print the figures as JSON.
    #[arg(long)]
    json: bool,
    /// Measure envs placed on hubs (a name, a list, `all` or counts, as `run --hub`) against
    /// the same envs here, and the remote round trip against a raw Zenoh one; with every env
    /// on one hub, also the batch against the raw Zenoh echo of its request and response bytes,
    /// alternated with the same batch here (p50, p99, remote / (here + echo), the remote rate
    /// against what the echo allows). The round trip uses the hub's `null-small` entry (serve
    /// it with ENVHUB_TEST_ADAPTERS=1 and `--registry @default --registry
    /// configs/bench/data_plane.yaml`).
    #[arg(long, value_name = "HUBS", default_value = "local")]
    hub: String,
}

/// The no-op entry a remote round trip is timed with.
const REMOTE_ROUND_TRIP_ID: &str = "null-small";
/// Bytes of a one-env `null-small` step request (header 24, action 8, seed 8, flag padded to
/// 8): the raw Zenoh round trip carries the same.
const REMOTE_ROUND_TRIP_BYTES: usize = 48;

/// Random action batches cycled through, so sampling is not what is measured.
const ACTION_POOL: usize = 64;

fn hub_throughput(env: &mut VecEnv, seconds: f64) -> anyhow::Result<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let pool: Vec<Vec<u8>> = (0..ACTION_POOL)
        .map(|_| env.sample_actions(&mut rng))
        .collect();
    env.reset(Some(0))?;
    for a in pool.iter().cycle().take(200) {
        env.step(a)?;
    }
    let (start, mut batches) = (Instant::now(), 0usize);
    while start.elapsed().as_secs_f64() < seconds {
        for a in &pool {
            env.step(a)?;
        }
        batches += pool.len();
    }
    Ok((batches * env.num_envs()) as f64 / start.elapsed().as_secs_f64())
}

fn inproc_throughput(
    env: &VecEnv,
    workers: usize,
    seconds: f64,
    hub_rate: f64,
) -> anyhow::Result<f64> {
    let route = env.route();
    let job = WorkerJob {
        adapter: route.adapter.clone(),
        env_id: route.env_id.clone(),
        config: route.config.clone(),
        env_offset: 0,
        worker_envs: env.num_envs(),
        session_envs: env.num_envs(),
        channel: ChannelName {
            prefix: String::new(),
            service: String::new(),
        },
        slots: SlotsName::new("", ""),
        worker_index: 0,
        session_workers: 0,
        owner_pid: std::process::id(),
        spin_us: 0,
        max_spin_us: 0,
        info_row_bytes: 0,
        python: None,
    };
    // Aim for about the same duration as the hub measurement.
    let steps = ((hub_rate * seconds) / env.num_envs() as f64).max(1000.0) as usize;
    let out = std::process::Command::new(envhub_hub::worker_binary())
        .args([
            "inproc",
            "--job",
            &serde_json::to_string(&job)?,
            "--threads",
            &workers.to_string(),
            "--steps",
            &steps.to_string(),
        ])
        .output()?;
    anyhow::ensure!(
        out.status.success(),
        "in-process run failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    Ok(v["steps_per_sec"].as_f64().unwrap_or(0.0))
}

/// p50 and p99 in µs.
fn percentiles(mut times: Vec<Duration>) -> (f64, f64) {
    times.sort();
    let n = times.len();
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    (us(times[n / 2]), us(times[(n * 99 / 100).min(n - 1)]))
}

/// A raw iceoryx2 round trip between this process and a worker process answering pings,
/// waiting the way envhub's channels wait: the floor under envhub's own round trip.
fn raw_round_trip(hub: &Hub, n: usize) -> anyhow::Result<(f64, f64)> {
    let prefix = hub.options().namespace.clone();
    let service = format!("envhub/pingpong/{}", std::process::id());
    let spin = hub.options().max_spin;
    let mut pong = std::process::Command::new(envhub_hub::worker_binary())
        .args(["pong", "--prefix", &prefix, "--service", &service])
        .args(["--spin-us", &spin.as_micros().to_string()])
        .spawn()?;
    let times = envhub_shm::ping(&prefix, &service, n, spin, Duration::from_secs(5));
    let _ = pong.kill();
    let _ = pong.wait();
    Ok(percentiles(times?))
}

fn round_trip(hub: &Hub, n: usize) -> anyhow::Result<(f64, f64)> {
    let config = EnvConfig {
        num_envs: 1,
        workers: Some(1),
        ..EnvConfig::default()
    };
    let env = hub.make_vec_direct("null", "Null-v0", &config)?;
    step_latencies(env, n)
}

/// p50 and p99 of `n` one-env steps of `env`, after a warm-up; closes it.
fn step_latencies(mut env: VecEnv, n: usize) -> anyhow::Result<(f64, f64)> {
    env.reset(Some(0))?;
    let action = vec![0u8; env.action_space().byte_len()];
    for _ in 0..1000 {
        env.step(&action)?;
    }
    let mut times = Vec::with_capacity(n);
    for _ in 0..n {
        let t = Instant::now();
        env.step(&action)?;
        times.push(t.elapsed());
    }
    env.close();
    Ok(percentiles(times))
}

/// Alternated blocks of [`batch_against_echo`].
const ECHO_BLOCKS: usize = 6;

/// One remote batch against the raw Zenoh echo of its bytes, in alternated blocks.
struct BatchAgainstEcho {
    remote: (f64, f64),
    here: (f64, f64),
    echo: (f64, f64),
}

impl BatchAgainstEcho {
    /// Remote / (here + echo) at p50 and p99, and the remote rate over what the echo allows
    /// (a batch here plus the echo of its bytes): at p50, the rates' ratio is the inverse.
    fn ratios(&self) -> (f64, f64, f64) {
        let (r, h, e) = (self.remote, self.here, self.echo);
        let p50 = r.0 / (h.0 + e.0);
        (p50, r.1 / (h.1 + e.1), 1.0 / p50)
    }

    fn json(&self) -> serde_json::Value {
        let (p50, p99, rate) = self.ratios();
        serde_json::json!({
            "blocks": ECHO_BLOCKS,
            "remote_batch_p50_us": self.remote.0,
            "remote_batch_p99_us": self.remote.1,
            "here_batch_p50_us": self.here.0,
            "here_batch_p99_us": self.here.1,
            "echo_p50_us": self.echo.0,
            "echo_p99_us": self.echo.1,
            "remote_over_here_plus_echo_p50": p50,
            "remote_over_here_plus_echo_p99": p99,
            "remote_rate_over_allowed": rate,
        })
    }

    fn print(&self) {
        let (r, h, e) = (self.remote, self.here, self.echo);
        println!("  alternated, {ECHO_BLOCKS} blocks of one batch each way:");
        println!(
            "    remote batch    p50 {:>9.1} µs, p99 {:>9.1} µs",
            r.0, r.1
        );
        println!(
            "    here            p50 {:>9.1} µs, p99 {:>9.1} µs",
            h.0, h.1
        );
        println!(
            "    raw echo        p50 {:>9.1} µs, p99 {:>9.1} µs  (its request and response bytes)",
            e.0, e.1
        );
        let (p50, p99, rate) = self.ratios();
        println!(
            "    remote / (here + echo)  p50 {p50:.2}, p99 {p99:.2}; remote rate / what the echo allows {rate:.2}"
        );
    }
}

/// A remote batch against what the wire allows, in one process pair: blocks of remote steps,
/// steps of the same envs here, and raw Zenoh echoes of the batch's bytes through the same
/// hub, alternated so that the machine's drift falls on all three alike. The echo carries the
/// request's bytes out and back, then the response's; half of the two is one round trip of a
/// request out and a response back (the hub's echo answers with what it was sent).
fn batch_against_echo(
    hub: &Hub,
    first: &str,
    remote: &mut VecEnv,
    local: &mut VecEnv,
    (request, response): (usize, usize),
    n: usize,
) -> anyhow::Result<BatchAgainstEcho> {
    let per_block = (n / ECHO_BLOCKS).max(20);
    let time_steps = |env: &mut VecEnv, out: &mut Vec<Duration>| -> anyhow::Result<()> {
        let action = vec![0u8; env.num_envs() * env.action_space().byte_len()];
        for _ in 0..per_block {
            let t = Instant::now();
            env.step(&action)?;
            out.push(t.elapsed());
        }
        Ok(())
    };
    let network = hub.network()?;
    let (mut on_hub, mut here, mut echo) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ECHO_BLOCKS {
        time_steps(remote, &mut on_hub)?;
        time_steps(local, &mut here)?;
        let out = network.echo_round_trips(first, request, per_block)?;
        let back = network.echo_round_trips(first, response, per_block)?;
        echo.extend(out.iter().zip(&back).map(|(a, b)| (*a + *b) / 2));
    }
    Ok(BatchAgainstEcho {
        remote: percentiles(on_hub),
        here: percentiles(here),
        echo: percentiles(echo),
    })
}

/// `--hub`: the same envs placed on hubs and here, the remote and the raw Zenoh round trip.
fn run_remote(
    hub: &Hub,
    args: &Args,
    placement: &envhub_hub::Placement,
) -> anyhow::Result<Outcome> {
    let config = EnvConfig {
        workers: Some(args.workers),
        ..EnvConfig::default()
    };
    let mut remote = hub.make_vec_on(&args.id, args.num_envs, &config, placement)?;
    let places = remote.placement();
    let (act_bytes, obs_bytes) = (
        remote.action_space().byte_len(),
        remote.observation_space().byte_len(),
    );
    let mut local = hub.make_vec(&args.id, args.num_envs, &config)?;
    // Alternated, best of two each: the machine is shared and its load drifts.
    let mut remote_rate: f64 = 0.0;
    let mut local_rate: f64 = 0.0;
    for _ in 0..2 {
        remote_rate = remote_rate.max(hub_throughput(&mut remote, args.seconds / 2.0)?);
        local_rate = local_rate.max(hub_throughput(&mut local, args.seconds / 2.0)?);
    }
    let first = places
        .iter()
        .map(|(p, _)| p.clone())
        .find(|p| p != envhub_hub::LOCAL)
        .ok_or_else(|| anyhow::anyhow!("`--hub {}` places no env on a hub", args.hub))?;
    let on_first = places
        .iter()
        .find(|(p, _)| *p == first)
        .map_or(0, |(_, r)| r.len());
    let request = 24 + envhub_shm::Layout::new(on_first, act_bytes).req_options;
    let response = 24 + envhub_shm::BatchLayout::new(on_first, obs_bytes, false).size();
    let batch = if places.len() == 1 {
        Some(batch_against_echo(
            hub,
            &first,
            &mut remote,
            &mut local,
            (request, response),
            args.round_trips.max(100),
        )?)
    } else {
        None
    };
    remote.close();
    local.close();
    let one = EnvConfig {
        workers: Some(1),
        ..EnvConfig::default()
    };
    let rt = hub
        .make_vec_on(
            REMOTE_ROUND_TRIP_ID,
            1,
            &one,
            &envhub_hub::Placement::Hubs(vec![first.clone()]),
        )
        .map_err(|e| {
            anyhow::anyhow!(
                "{e}\nhint: the round trip uses hub `{first}`'s `{REMOTE_ROUND_TRIP_ID}` entry: serve it with ENVHUB_TEST_ADAPTERS=1 envhub --registry @default --registry configs/bench/data_plane.yaml serve ..."
            )
        })?;
    let n = args.round_trips.max(100);
    let (p50, p99) = step_latencies(rt, n)?;
    let (raw50, raw99) = percentiles(hub.network()?.echo_round_trips(
        &first,
        REMOTE_ROUND_TRIP_BYTES,
        n,
    )?);
    // The model of docs/guide/remote.md: a batch on one hub takes what it takes here plus one
    // round trip of its request and response bytes: the alternated echo's where it ran, else a
    // raw echo of that many bytes, half each way.
    let bulk50 = match &batch {
        Some(b) => b.echo.0,
        None => {
            percentiles(hub.network()?.echo_round_trips(
                &first,
                (request + response) / 2,
                (n / 10).max(100),
            )?)
            .0
        }
    };
    let predicted = if places.len() == 1 {
        let batch = args.num_envs as f64 / local_rate;
        Some(args.num_envs as f64 / (batch + bulk50 * 1e-6))
    } else {
        None
    };
    let placed: Vec<String> = places
        .iter()
        .map(|(p, r)| format!("{p}:{}", r.len()))
        .collect();
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "id": args.id,
                "num_envs": args.num_envs,
                "workers": args.workers,
                "placement": placed,
                "remote_steps_per_sec": remote_rate,
                "local_steps_per_sec": local_rate,
                "remote_over_local": remote_rate / local_rate,
                "remote_roundtrip_p50_us": p50,
                "remote_roundtrip_p99_us": p99,
                "raw_zenoh_p50_us": raw50,
                "raw_zenoh_p99_us": raw99,
                "remote_over_raw_p50": p50 / raw50,
                "request_bytes": request,
                "response_bytes": response,
                "raw_zenoh_batch_bytes_p50_us": bulk50,
                "model_steps_per_sec": predicted,
                "batch_against_echo": batch.as_ref().map(BatchAgainstEcho::json),
            })
        );
    } else {
        println!(
            "{} with {} envs, {} workers per machine, placed {}",
            args.id,
            args.num_envs,
            args.workers,
            placed.join(", ")
        );
        println!("  on the hubs       {remote_rate:>12.0} steps/s");
        println!("  here              {local_rate:>12.0} steps/s  (same envs on this machine)");
        println!("  hubs / here       {:>12.2}", remote_rate / local_rate);
        println!("  remote round trip p50 {p50:.1} µs, p99 {p99:.1} µs  (no-op env on `{first}`)");
        println!(
            "  raw Zenoh         p50 {raw50:.1} µs, p99 {raw99:.1} µs  (echo, {REMOTE_ROUND_TRIP_BYTES} B, same QoS; envhub p50 is {:.2}×)",
            p50 / raw50
        );
        println!(
            "  one batch's bytes {request} B request, {response} B response: raw Zenoh echo p50 {bulk50:.1} µs"
        );
        if let Some(p) = predicted {
            println!(
                "  model             {p:>12.0} steps/s  (here + that echo per batch; docs/guide/remote.md)"
            );
        }
        if let Some(b) = &batch {
            b.print();
        }
    }
    Ok(Outcome::Done)
}

pub(crate) fn run(hub: &Hub, args: &Args) -> anyhow::Result<Outcome> {
    let placement: envhub_hub::Placement = args.hub.parse()?;
    if !placement.is_local() {
        return run_remote(hub, args, &placement);
    }
    let config = EnvConfig {
        workers: Some(args.workers),
        ..EnvConfig::default()
    };
    let started = Instant::now();
    let mut env = hub.make_vec(&args.id, args.num_envs, &config)?;
    env.reset(Some(0))?;
    let start_ms = started.elapsed().as_secs_f64() * 1e3;
    let hub_rate = hub_throughput(&mut env, args.seconds)?;
    let copied_per_step = env.obs_bytes_copied() as f64 / env.steps_taken().max(1) as f64;
    let inproc_rate = inproc_throughput(&env, args.workers, args.seconds, hub_rate)?;
    env.close();
    let (p50, p99) = round_trip(hub, args.round_trips.max(100))?;
    let (raw50, raw99) = raw_round_trip(hub, args.round_trips.max(100))?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "id": args.id,
                "num_envs": args.num_envs,
                "workers": args.workers,
                "hub_steps_per_sec": hub_rate,
                "inproc_steps_per_sec": inproc_rate,
                "obs_bytes_copied_per_step": copied_per_step,
                "roundtrip_p50_us": p50,
                "roundtrip_p99_us": p99,
                "raw_iceoryx2_p50_us": raw50,
                "raw_iceoryx2_p99_us": raw99,
                "start_ms": start_ms,
            })
        );
    } else {
        println!(
            "{} with {} envs on {} workers",
            args.id, args.num_envs, args.workers
        );
        println!("  through the hub   {hub_rate:>12.0} steps/s");
        println!(
            "  in-process        {inproc_rate:>12.0} steps/s  (same envs, {} threads, no IPC)",
            args.workers
        );
        println!("  hub / in-process  {:>12.2}", hub_rate / inproc_rate);
        println!("  obs bytes copied  {copied_per_step:>12.0} per step");
        println!("  round trip        p50 {p50:.1} µs, p99 {p99:.1} µs  (no-op env)");
        println!(
            "  raw iceoryx2      p50 {raw50:.1} µs, p99 {raw99:.1} µs  (ping-pong, same wait; envhub p50 is {:.2}×)",
            p50 / raw50
        );
        println!("  start             {start_ms:.0} ms  (make + first reset)");
    }
    Ok(Outcome::Done)
}
