//! Workers live as long as their owner and no longer: a Ctrl-C in the client's terminal
//! (SIGINT to its process group) does not reach them, a client killed in the middle of a
//! step takes its workers with it at once, and a session outlives the thread that made it.
//!
//! The clients are this test binary run again in a helper mode (`client_helper`).

use envhub_e2e::{TestHub, sigkill};
use envhub_hub::{EnvConfig, Hub, Registry, SessionOptions};
use std::io::BufRead;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const MODE: &str = "E2E_CLIENT_MODE";
const NAMESPACE: &str = "E2E_CLIENT_NAMESPACE";

/// This binary as a client in `mode`, its stdout lines sent to the returned channel.
fn client(mode: &str, namespace: &str, own_group: bool) -> (Child, mpsc::Receiver<String>) {
    let mut command = Command::new(std::env::current_exe().unwrap());
    command
        .args(["--exact", "worker_lifetime::client_helper", "--nocapture"])
        .env(MODE, mode)
        .env(NAMESPACE, namespace)
        .stdout(Stdio::piped());
    if own_group {
        // Its own process group, as a shell gives a foreground job: the SIGINT of a Ctrl-C
        // goes to that group, and never to this test runner.
        std::os::unix::process::CommandExt::process_group(&mut command, 0);
    }
    let mut child = command.spawn().unwrap();
    let out = std::io::BufReader::new(child.stdout.take().unwrap());
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in out.lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (child, rx)
}

/// The first line starting with `prefix` within `timeout`, without the prefix.
fn expect_line(lines: &mpsc::Receiver<String>, prefix: &str, timeout: Duration) -> String {
    let deadline = Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) if line.starts_with(prefix) => return line[prefix.len()..].trim().into(),
            Ok(_) => {}
            Err(e) => panic!("no line `{prefix}…` from the client within {timeout:?}: {e}"),
        }
    }
}

/// Field `index` (1-based, as in proc(5)) of `/proc/<pid>/stat`; None if it has gone.
fn stat_field(pid: u32, index: usize) -> Option<String> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after = &stat[stat.rfind(')')? + 2..];
    after.split_whitespace().nth(index - 3).map(str::to_string)
}

/// Whether `pid` has exited (a zombie that nobody reaped yet counts as exited).
fn exited(pid: u32) -> bool {
    stat_field(pid, 3).is_none_or(|state| state == "Z" || state == "X")
}

fn namespace(test: &str) -> String {
    format!("e2e_{test}_{}_", std::process::id())
}

#[test]
fn a_killed_client_takes_its_worker_with_it_in_the_middle_of_a_step() {
    let ns = namespace("pdeath");
    let (mut client, lines) = client("step", &ns, false);
    let worker: u32 = expect_line(&lines, "worker ", Duration::from_secs(20))
        .parse()
        .unwrap();
    expect_line(&lines, "stepping", Duration::from_secs(5));
    // Inside the 30 s step now: the worker's loop will not look at its owner for a while.
    std::thread::sleep(Duration::from_millis(300));
    assert!(!exited(worker), "the worker is stepping");
    sigkill(client.id());
    client.wait().unwrap();
    let start = Instant::now();
    while !exited(worker) {
        assert!(
            start.elapsed() < Duration::from_secs(1),
            "worker {worker} still runs 1 s after its client was killed"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = envhub_shm::remove_namespace(&ns);
}

#[test]
fn ctrl_c_in_the_clients_terminal_does_not_reach_its_workers() {
    let ns = namespace("sigint");
    let (mut client, lines) = client("sigint", &ns, true);
    let workers: Vec<u32> = expect_line(&lines, "workers ", Duration::from_secs(20))
        .split(',')
        .map(|p| p.parse().unwrap())
        .collect();
    let group = stat_field(client.id(), 5).unwrap();
    for &w in &workers {
        assert_ne!(
            stat_field(w, 5).unwrap(),
            group,
            "worker {w} is in the client's process group"
        );
    }
    // The terminal's Ctrl-C: SIGINT to the foreground process group.
    // SAFETY: kill has no memory effects.
    assert_eq!(
        unsafe { libc::kill(-(client.id() as libc::pid_t), libc::SIGINT) },
        0
    );
    let after = expect_line(&lines, "after SIGINT: ", Duration::from_secs(20));
    assert_eq!(after, "stepped", "the client's session after Ctrl-C");
    let status = client.wait().unwrap();
    assert!(status.success(), "{status}");
    let _ = envhub_shm::remove_namespace(&ns);
}

#[test]
fn a_session_outlives_the_thread_that_made_it() {
    let t = std::sync::Arc::new(TestHub::new("madeonthread"));
    let maker = t.clone();
    let config = EnvConfig {
        workers: Some(2),
        ..EnvConfig::default()
    };
    let mut env = std::thread::spawn(move || maker.hub.make_vec("gym-cartpole", 4, &config))
        .join()
        .unwrap()
        .unwrap();
    // The thread has ended: its workers must not have gone with it.
    std::thread::sleep(Duration::from_millis(300));
    for &pid in &env.worker_pids() {
        assert!(!exited(pid), "worker {pid} exited with the thread");
    }
    env.reset(Some(0)).unwrap();
    for _ in 0..20 {
        env.step_i64(&[0, 1, 1, 0]).unwrap();
    }
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// The client processes of the tests above; does nothing in a normal run.
#[test]
fn client_helper() {
    let (Ok(mode), Ok(ns)) = (std::env::var(MODE), std::env::var(NAMESPACE)) else {
        return;
    };
    let hub = Hub::new(Registry::builtin()).with_options(SessionOptions {
        namespace: ns,
        ..SessionOptions::default()
    });
    let one_worker = EnvConfig {
        workers: Some(1),
        ..EnvConfig::default()
    };
    match mode.as_str() {
        "step" => {
            let mut config = one_worker;
            config.extra.insert("sleep_ms".into(), 30_000.into());
            let mut env = hub.make_vec_direct("null", "Null-v0", &config).unwrap();
            env.reset(None).unwrap();
            println!("worker {}", env.worker_pids()[0]);
            println!("stepping");
            let _ = env.step(&[0u8; 8]);
            println!("the step returned: the client was not killed");
        }
        "sigint" => {
            // A handler, not SIG_IGN: that would be inherited by the workers it starts.
            // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
            unsafe { libc::signal(libc::SIGINT, on_sigint as *const () as libc::sighandler_t) };
            let config = EnvConfig {
                workers: Some(2),
                ..EnvConfig::default()
            };
            let mut env = hub.make_vec("gym-cartpole", 2, &config).unwrap();
            env.reset(Some(0)).unwrap();
            let pids: Vec<String> = env.worker_pids().iter().map(u32::to_string).collect();
            println!("workers {}", pids.join(","));
            let deadline = Instant::now() + Duration::from_secs(20);
            while !INTERRUPTED.load(Ordering::SeqCst) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
            }
            // Give a SIGINT that reached the workers time to end them.
            std::thread::sleep(Duration::from_millis(200));
            match env.step_i64(&[0, 1]) {
                Ok(_) => println!("after SIGINT: stepped"),
                Err(e) => println!("after SIGINT: {}", e.to_string().replace('\n', " ")),
            }
            env.close();
        }
        other => panic!("unknown client mode `{other}`"),
    }
}
