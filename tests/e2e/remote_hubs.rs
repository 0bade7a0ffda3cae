//! Hubs across machines, simulated on loopback: several `envhub serve` processes, each with its
//! own iceoryx2 namespace, multicast off and explicit endpoints; real Zenoh sessions.

use envhub_e2e::remote::{RemoteHub, client, net_to};
use envhub_e2e::{TestHub, mujoco_available, sigkill};
use envhub_hub::{EnvConfig, Hub, HubError, Placement};
use rand::SeedableRng;
use std::time::{Duration, Instant};

fn hubs(names: &[&RemoteHub]) -> Placement {
    Placement::Hubs(names.iter().map(|h| h.name.clone()).collect())
}

/// Steps `remote` and `local` (same id, config, seeds, actions) side by side and asserts
/// every result is equal bit for bit.
pub(crate) fn assert_same_rollout(
    remote: &mut envhub_hub::VecEnv,
    local: &mut envhub_hub::VecEnv,
    steps: usize,
) {
    let a = remote.reset(Some(11)).unwrap();
    let (obs, infos) = (
        a.obs.to_vec(),
        (0..a.env_ids.len())
            .map(|k| a.info(k).clone())
            .collect::<Vec<_>>(),
    );
    let b = local.reset(Some(11)).unwrap();
    assert_eq!(obs, b.obs, "reset observations");
    for (k, info) in infos.iter().enumerate() {
        assert_eq!(info, b.info(k), "reset info of env {k}");
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut episodes = 0;
    for t in 0..steps {
        let actions = local.sample_actions(&mut rng);
        let a = remote.step(&actions).unwrap();
        let got = (
            a.obs.to_vec(),
            a.rewards.to_vec(),
            a.terminated.to_vec(),
            a.truncated.to_vec(),
            (0..a.env_ids.len())
                .map(|k| a.info(k).clone())
                .collect::<Vec<_>>(),
        );
        let b = local.step(&actions).unwrap();
        assert_eq!(got.0, b.obs, "obs at step {t}");
        assert_eq!(got.1, b.rewards, "rewards at step {t}");
        assert_eq!(got.2, b.terminated, "terminated at step {t}");
        assert_eq!(got.3, b.truncated, "truncated at step {t}");
        for (k, info) in got.4.iter().enumerate() {
            assert_eq!(info, b.info(k), "info of env {k} at step {t}");
        }
        episodes += b
            .terminated
            .iter()
            .chain(b.truncated)
            .filter(|d| **d)
            .count();
    }
    assert!(episodes > 0, "the rollout went through no autoreset");
}

#[test]
fn a_session_over_two_hubs_equals_local_stepping_bit_for_bit() {
    let a = RemoteHub::start("a", &[], &[]);
    let b = RemoteHub::start("b", &[], &[]);
    let hub = client("bitexact", &[&a, &b]);
    let local = TestHub::new("remote_bitexact");
    let config = EnvConfig::default();
    let mut remote = hub
        .make_vec_on("gym-cartpole", 8, &config, &hubs(&[&a, &b]))
        .unwrap();
    assert_eq!(
        remote.placement(),
        vec![("a".to_string(), 0..4), ("b".to_string(), 4..8)]
    );
    let mut here = local.hub.make_vec("gym-cartpole", 8, &config).unwrap();
    assert_same_rollout(&mut remote, &mut here, 300);

    if !mujoco_available(
        &local.hub,
        "a_session_over_two_hubs_equals_local_stepping_bit_for_bit",
    ) {
        return;
    }
    let config = EnvConfig {
        max_episode_steps: Some(40),
        ..EnvConfig::default()
    };
    let mut remote = hub
        .make_vec_on("mujoco-ant", 4, &config, &hubs(&[&a, &b]))
        .unwrap();
    let mut here = local.hub.make_vec("mujoco-ant", 4, &config).unwrap();
    assert_same_rollout(&mut remote, &mut here, 100);
}

#[test]
fn local_and_remote_envs_mix_in_one_session() {
    let a = RemoteHub::start("mixa", &[], &[]);
    let hub = client("mix", &[&a]);
    let local = TestHub::new("remote_mix");
    let placement: Placement = "local:3,mixa:3".parse().unwrap();
    let config = EnvConfig::default();
    let mut mixed = hub
        .make_vec_on("gym-cartpole", 6, &config, &placement)
        .unwrap();
    assert_eq!(
        mixed.placement(),
        vec![("local".to_string(), 0..3), ("mixa".to_string(), 3..6)]
    );
    let mut here = local.hub.make_vec("gym-cartpole", 6, &config).unwrap();
    assert_same_rollout(&mut mixed, &mut here, 200);
    // send/recv across the two: both halves come back, each exactly once.
    let actions = vec![0u8; 6 * 8];
    mixed.send(&actions, &[0, 1, 2, 3, 4, 5]).unwrap();
    let mut seen = Vec::new();
    while seen.len() < 6 {
        seen.extend_from_slice(mixed.recv().unwrap().env_ids);
    }
    seen.sort();
    assert_eq!(seen, vec![0, 1, 2, 3, 4, 5]);
}

/// Steps until an error; it must be `HubLost` naming `hub`, within `limit` of `since`.
fn expect_lost(env: &mut envhub_hub::VecEnv, hub: &str, since: Instant, limit: Duration) {
    let actions = vec![0u8; env.num_envs() * 8];
    let err = loop {
        match env.step(&actions) {
            Ok(_) => assert!(since.elapsed() < limit, "still stepping after {limit:?}"),
            Err(e) => break e,
        }
    };
    let took = since.elapsed();
    match &err {
        HubError::HubLost {
            hub: lost, envs, ..
        } => {
            assert_eq!(lost, hub, "{err}");
            assert_eq!(envs, "2..4", "{err}");
        }
        other => panic!("expected HubLost, got {other}"),
    }
    assert!(took < limit, "lost after {took:?}: {err}");
    eprintln!("hub `{hub}` lost after {took:?}");
}

#[test]
fn a_killed_hub_is_reported_lost_within_a_second() {
    let a = RemoteHub::start("ka", &[], &[]);
    let b = RemoteHub::start("kb", &[], &[]);
    let hub = client("killed", &[&a, &b]);
    let mut env = hub
        .make_vec_on("gym-cartpole", 4, &EnvConfig::default(), &hubs(&[&a, &b]))
        .unwrap();
    env.reset(Some(0)).unwrap();
    sigkill(b.pid());
    expect_lost(&mut env, "kb", Instant::now(), Duration::from_secs(1));
    // The other hub is unaffected: a new session on it works.
    let mut again = hub
        .make_vec_on("gym-cartpole", 2, &EnvConfig::default(), &hubs(&[&a]))
        .unwrap();
    again.reset(Some(0)).unwrap();
}

#[test]
fn a_frozen_hub_is_reported_lost_within_two_seconds() {
    let a = RemoteHub::start("fa", &[], &[]);
    let b = RemoteHub::start("fb", &[], &[]);
    let hub = client("frozen", &[&a, &b]);
    let mut env = hub
        .make_vec_on("gym-cartpole", 4, &EnvConfig::default(), &hubs(&[&a, &b]))
        .unwrap();
    env.reset(Some(0)).unwrap();
    let stopped = std::process::Command::new("kill")
        .args(["-STOP", &b.pid().to_string()])
        .status()
        .unwrap();
    assert!(stopped.success());
    expect_lost(&mut env, "fb", Instant::now(), Duration::from_secs(2));
}

#[test]
fn a_dead_client_s_sessions_end_on_their_hubs() {
    let a = RemoteHub::start("da", &[], &[]);
    let mut client = std::process::Command::new(envhub_e2e::binary("envhub"))
        .args([
            "--connect",
            &a.endpoint,
            "run",
            "gym-cartpole",
            "--hub",
            "da",
        ])
        .args([
            "--num-envs",
            "4",
            "--workers",
            "2",
            "--steps",
            "1000000000000",
        ])
        .env(envhub_hub::ENVHUB_MULTICAST, "0")
        .env(
            "ENVHUB_NAMESPACE",
            format!("e2e_deadclient_{}_", std::process::id()),
        )
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while a.worker_count() < 2 {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "the remote session never started"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let slots_before = envhub_e2e::shm_files(&a.namespace);
    assert!(
        !slots_before.is_empty(),
        "the hub's session has shared memory"
    );
    sigkill(client.id());
    let _ = client.wait();
    let killed = Instant::now();
    // Its workers stop, and its batch slots and channels leave /dev/shm (iceoryx2 keeps one
    // management file per namespace, shared by every session).
    let left = || -> Vec<String> {
        envhub_e2e::shm_files(&a.namespace)
            .into_iter()
            .filter(|f| !f.contains("global"))
            .collect()
    };
    while a.worker_count() > 0 || !left().is_empty() {
        assert!(
            killed.elapsed() < Duration::from_secs(2),
            "2 s after the client died the hub still runs {} of its workers; left in /dev/shm: {:?}",
            a.worker_count(),
            left()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    eprintln!(
        "sessions ended {:?} after the client died",
        killed.elapsed()
    );
}

/// What an observer of a session's traffic forges, each time it sees an answer.
/// The fake answers it sends go to `fakes` first (the observer does not forge from its own).
fn forge_on_answer(
    spy: &zenoh::Session,
    answer_key: &str,
    answer: &[u8],
    request_len: usize,
    fakes: &std::sync::Mutex<std::collections::HashSet<Vec<u8>>>,
) {
    use zenoh::Wait;
    let seq = u64::from_le_bytes(answer[..8].try_into().unwrap());
    let request_key = answer_key.replace("/rep", "/req");
    // The session's next request, as the observer can write it: the next sequence number, a
    // CLOSE (then a STEP, then a RESET), the right size, and a tag of its own invention.
    for command in [
        envhub_shm::command::CLOSE,
        envhub_shm::command::STEP,
        envhub_shm::command::RESET,
    ] {
        let mut forged = vec![0u8; request_len];
        forged[..8].copy_from_slice(&(seq + 1).to_le_bytes());
        forged[8..12].copy_from_slice(&command.to_le_bytes());
        forged[12..16].copy_from_slice(&2u32.to_le_bytes());
        let _ = spy.put(&request_key, forged).wait();
    }
    // The answer the client waits for next, and garbage, on the answers' key.
    let mut fake = answer.to_vec();
    fake[..8].copy_from_slice(&(seq + 1).to_le_bytes());
    fake[8..12].copy_from_slice(&envhub_shm::status::CLOSED.to_le_bytes());
    fakes.lock().unwrap().insert(fake.clone());
    let _ = spy.put(answer_key, fake).wait();
    let _ = spy.put(answer_key, vec![0xffu8; 5]).wait();
    let _ = spy
        .put(answer_key, answer[..answer.len() - 1].to_vec())
        .wait();
}

/// An observer on the session's Zenoh network (the client connects to it, so it sees every
/// request and answer and can put on the session's keys) learns the session's keys and
/// sequence numbers from the traffic and forges the next request (close, step, reset),
/// the next answer, garbage, and replays of old requests and answers. None of it is taken:
/// the victim's rollout is bit for bit the one of a session nobody attacked.
#[test]
fn an_observer_of_a_session_can_neither_steer_it_nor_forge_its_answers() {
    use std::sync::{Arc, Mutex};
    use zenoh::Wait;
    const STEPS: usize = 100;
    let a = RemoteHub::start("ga", &[], &[]);
    let spy_endpoint = format!("tcp/127.0.0.1:{}", envhub_e2e::remote::free_port());
    let mut spy_net = net_to(&[&a]);
    spy_net.listen = vec![spy_endpoint.clone()];
    let spy = zenoh::open(spy_net.zenoh_config(false).unwrap())
        .wait()
        .unwrap();
    let mut net = net_to(&[&a]);
    net.connect.push(spy_endpoint);
    let hub = Hub::new(envhub_hub::Registry::builtin()).with_network(net);
    let rollout = |env: &mut envhub_hub::VecEnv| envhub_e2e::rollout_bytes(env, 1, 9, STEPS);
    // The session nobody attacks.
    let mut quiet = hub
        .make_vec_on("gym-cartpole", 2, &EnvConfig::default(), &hubs(&[&a]))
        .unwrap();
    let expected = rollout(&mut quiet);
    quiet.close();
    // The observer: every request and answer it sees, kept for replays; on every answer, a
    // forged next request and next answer.
    /// Messages seen: (key, bytes).
    type Seen = Arc<Mutex<Vec<(String, Vec<u8>)>>>;
    let requests: Seen = Arc::default();
    let answers: Seen = Arc::default();
    let _requests = {
        let requests = requests.clone();
        spy.declare_subscriber("envhub/session/ga/*/req")
            .callback(move |s| {
                requests.lock().unwrap().push((
                    s.key_expr().as_str().to_string(),
                    s.payload().to_bytes().into_owned(),
                ));
            })
            .wait()
            .unwrap()
    };
    let forged = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let fakes: Arc<Mutex<std::collections::HashSet<Vec<u8>>>> = Arc::default();
    let _answers = {
        let (answers, requests, spy2, forged, fakes) = (
            answers.clone(),
            requests.clone(),
            spy.clone(),
            forged.clone(),
            fakes.clone(),
        );
        spy.declare_subscriber("envhub/session/ga/*/rep")
            .callback(move |s| {
                thread_local! {
                    // The spy's own puts come back to it on this thread: not worked from.
                    static FORGING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
                }
                if FORGING.with(|f| f.get()) {
                    return;
                }
                let key = s.key_expr().as_str().to_string();
                let bytes = s.payload().to_bytes().into_owned();
                // Only what the hub sent (24 bytes of header at least) is worked from.
                if bytes.len() < 40 || fakes.lock().unwrap().contains(&bytes) {
                    return;
                }
                let request_len = requests.lock().unwrap().last().map(|(_, r)| r.len());
                if let Some(len) = request_len
                    && forged.load(std::sync::atomic::Ordering::Relaxed) < 10_000
                {
                    FORGING.with(|f| f.set(true));
                    forge_on_answer(&spy2, &key, &bytes, len, &fakes);
                    FORGING.with(|f| f.set(false));
                    forged.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                answers.lock().unwrap().push((key, bytes));
            })
            .wait()
            .unwrap()
    };
    let unsealed_before = envhub_hub::UNSEALED.load(std::sync::atomic::Ordering::Relaxed);
    let mut victim = hub
        .make_vec_on("gym-cartpole", 2, &EnvConfig::default(), &hubs(&[&a]))
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let mut got = vec![victim.reset(Some(1)).unwrap().obs.to_vec()];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    for t in 0..STEPS {
        // Replays of every request and answer seen so far but the newest two, then the step.
        if t % 10 == 5 {
            let old: Vec<(String, Vec<u8>)> = {
                let r = requests.lock().unwrap();
                r.iter().rev().skip(2).cloned().collect()
            };
            for (key, bytes) in old {
                spy.put(key, bytes).wait().unwrap();
            }
            let old: Vec<(String, Vec<u8>)> = {
                let r = answers.lock().unwrap();
                r.iter().rev().skip(2).take(20).cloned().collect()
            };
            for (key, bytes) in old {
                spy.put(key, bytes).wait().unwrap();
            }
        }
        got.push(envhub_e2e::step_bytes(&mut victim, &mut rng));
    }
    let forged = forged.load(std::sync::atomic::Ordering::Relaxed);
    assert!(
        forged >= STEPS,
        "the observer saw {forged} answers: it did not see the session's traffic"
    );
    assert!(
        got == expected,
        "the attacked rollout differs from the quiet one"
    );
    let unsealed =
        envhub_hub::UNSEALED.load(std::sync::atomic::Ordering::Relaxed) - unsealed_before;
    assert!(
        unsealed >= forged as u64,
        "{forged} forged answers were sent, {unsealed} were dropped as unsealed"
    );
    // The session and the hub go on.
    victim.step(&[0u8; 16]).unwrap();
    let mut other = hub
        .make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &hubs(&[&a]))
        .unwrap();
    other.reset(None).unwrap();
    eprintln!("{forged} rounds of forgeries, {unsealed} answers dropped as unsealed");
}

fn expect_refused(result: Result<envhub_hub::VecEnv, HubError>, needle: &str) {
    match result {
        Err(e @ HubError::Refused { .. }) => {
            assert!(e.to_string().contains(needle), "{e}");
        }
        Err(e) => panic!("expected a refusal naming {needle:?}, got {e}"),
        Ok(_) => panic!("expected a refusal naming {needle:?}, got a session"),
    }
}

#[test]
fn remote_clients_cannot_name_files_and_the_hub_s_limits_hold() {
    // One client may take all of it here (the shares are `fair_shares`' test).
    let a = RemoteHub::start(
        "sa",
        &[
            "--max-envs",
            "4",
            "--max-workers",
            "2",
            "--max-envs-per-client",
            "0",
            "--max-workers-per-client",
            "0",
        ],
        &[],
    );
    let hub = client("security", &[&a]);
    let on_a = hubs(&[&a]);
    let with_asset = EnvConfig {
        asset_path: Some("/etc/passwd".into()),
        ..EnvConfig::default()
    };
    expect_refused(
        hub.make_vec_on("mujoco-ant", 1, &with_asset, &on_a),
        "asset_path",
    );
    let mut with_xml = EnvConfig::default();
    with_xml
        .extra
        .insert("xml_file".into(), serde_json::json!("/tmp/evil.xml"));
    expect_refused(
        hub.make_vec_on("mujoco-ant", 1, &with_xml, &on_a),
        "xml_file",
    );
    expect_refused(
        hub.make_vec_on("gym-cartpole", 5, &EnvConfig::default(), &on_a),
        "limit of 4",
    );
    let three_workers = EnvConfig {
        workers: Some(3),
        ..EnvConfig::default()
    };
    expect_refused(
        hub.make_vec_on("gym-cartpole", 3, &three_workers, &on_a),
        "limit of 2",
    );
    assert_eq!(a.worker_count(), 0, "a refused request started workers");
    // An id outside the hub's catalog is the registry's error, with the closest ids.
    match hub.make_vec_on("gym-cartpol", 1, &EnvConfig::default(), &on_a) {
        Err(e) => assert!(e.to_string().contains("gym-cartpole"), "{e}"),
        Ok(_) => panic!("an unknown id made a session"),
    }
    // Within the limits, it serves.
    let mut ok = hub
        .make_vec_on("gym-cartpole", 4, &EnvConfig::default(), &on_a)
        .unwrap();
    ok.reset(Some(0)).unwrap();
    expect_refused(
        hub.make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &on_a),
        "it runs 4",
    );
}

#[test]
fn a_client_with_wrong_credentials_sees_no_hub() {
    let dir = std::env::temp_dir().join(format!("e2e-auth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let dictionary = dir.join("credentials.txt");
    std::fs::write(&dictionary, "trainer:s3cret\nhub:hubpass\n").unwrap();
    let hub_config = dir.join("hub.json5");
    std::fs::write(
        &hub_config,
        format!(
            r#"{{ transport: {{ auth: {{ usrpwd: {{ user: "hub", password: "hubpass", dictionary_file: "{}" }} }} }} }}"#,
            dictionary.display()
        ),
    )
    .unwrap();
    let a = RemoteHub::start(
        "auth",
        &["--zenoh-config", hub_config.to_str().unwrap()],
        &[],
    );
    let with_credentials = |user: &str, password: &str| {
        let file = dir.join(format!("client-{user}-{password}.json5"));
        std::fs::write(
            &file,
            format!(
                r#"{{ transport: {{ auth: {{ usrpwd: {{ user: "{user}", password: "{password}" }} }} }} }}"#
            ),
        )
        .unwrap();
        let mut net = net_to(&[&a]);
        net.config = Some(file);
        Hub::new(envhub_hub::Registry::builtin()).with_network(net)
    };
    let intruder = with_credentials("trainer", "wrong");
    assert!(
        intruder.hubs().unwrap().is_empty(),
        "wrong credentials see a hub"
    );
    assert!(
        intruder
            .make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &hubs(&[&a]))
            .is_err()
    );
    assert_eq!(a.worker_count(), 0);
    let trainer = with_credentials("trainer", "s3cret");
    let seen: Vec<String> = trainer
        .hubs()
        .unwrap()
        .into_iter()
        .map(|h| h.name)
        .collect();
    assert_eq!(seen, vec!["auth".to_string()]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn hubs_list_their_info_and_unknown_names_get_the_closest() {
    let a = RemoteHub::start("alpha", &[], &[]);
    let b = RemoteHub::start("beta", &[], &[]);
    let hub = client("list", &[&a, &b]);
    let infos = hub.hubs().unwrap();
    let names: Vec<&str> = infos.iter().map(|h| h.name.as_str()).collect();
    assert_eq!(names, vec!["alpha", "beta"]);
    assert!(infos.iter().all(|h| h.cores >= 1 && h.catalog > 50));
    assert!(infos[0].adapters.contains(&"classic_control".to_string()));
    let err = hub
        .make_vec_on(
            "gym-cartpole",
            2,
            &EnvConfig::default(),
            &"alpah".parse().unwrap(),
        )
        .err()
        .expect("an unknown hub");
    let text = err.to_string();
    assert!(
        text.contains("closest: alpha") && text.contains("alpha, beta"),
        "{text}"
    );
    let registry = hub.remote_registry("beta").unwrap();
    assert!(registry.get("gym-cartpole").is_ok());
    assert!(
        hub.remote_adapters("alpha")
            .unwrap()
            .iter()
            .any(|x| x.name == "classic_control")
    );
}

#[test]
fn with_restart_on_crash_a_lost_hub_s_envs_move_to_the_hubs_that_remain() {
    let a = RemoteHub::start("ra", &[], &[]);
    let b = RemoteHub::start("rb", &[], &[]);
    let hub = client("replace", &[&a, &b]);
    let options = envhub_hub::SessionOptions {
        restart_on_crash: true,
        ..hub.options().clone()
    };
    let hub = hub.with_options(options);
    let mut env = hub
        .make_vec_on("gym-cartpole", 4, &EnvConfig::default(), &hubs(&[&a, &b]))
        .unwrap();
    env.reset(Some(0)).unwrap();
    let actions = [0u8; 32];
    env.step(&actions).unwrap();
    let endpoint = b.endpoint.clone();
    sigkill(b.pid());
    let start = Instant::now();
    // Steps go on; the first one after the loss brings envs 2..4 back reset and truncated.
    let moved = loop {
        let batch = env.step(&actions).unwrap();
        if batch.truncated[2] && batch.truncated[3] {
            break (0..4).map(|k| batch.info(k).clone()).collect::<Vec<_>>();
        }
        assert!(
            start.elapsed() < Duration::from_secs(3),
            "the envs never moved"
        );
    };
    assert_eq!(moved[2]["hub_lost"], "rb", "{:?}", moved[2]);
    assert_eq!(moved[3]["worker_restarted"], true, "{:?}", moved[3]);
    assert!(moved[0].get("hub_lost").is_none(), "{:?}", moved[0]);
    assert_eq!(
        env.placement(),
        vec![("ra".to_string(), 0..4)],
        "envs 2..4 now run on ra"
    );
    for _ in 0..20 {
        env.step(&actions).unwrap();
    }
    drop(b);
    // A hub that comes back is live again.
    let _b = RemoteHub::start_at("rb", &endpoint, &[], &[]);
    let start = Instant::now();
    loop {
        let names: Vec<String> = hub.hubs().unwrap().into_iter().map(|h| h.name).collect();
        if names.contains(&"rb".to_string()) {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "rb is not live again: {names:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    eprintln!("rb live again {:?} after it restarted", start.elapsed());
}

/// `envhub run` on a remote hub, as its own process, with `cipher` offered alone
/// (`ENVHUB_SESSION_CIPHER`; `None`: the default offer): (exit code, stdout, stderr).
fn run_remote(hub: &RemoteHub, cipher: Option<&str>) -> (i32, String, String) {
    let mut cmd = std::process::Command::new(envhub_e2e::binary("envhub"));
    cmd.args(["--connect", &hub.endpoint, "run", "gym-cartpole", "--hub"])
        .arg(&hub.name)
        .args([
            "--num-envs",
            "4",
            "--workers",
            "1",
            "--steps",
            "400",
            "--seed",
            "3",
            "--json",
        ])
        .env(envhub_hub::ENVHUB_MULTICAST, "0")
        .env_remove(envhub_hub::ENVHUB_CONNECT)
        .env("ENVHUB_KNOWN_HUBS", envhub_e2e::remote::known_hubs())
        .env_remove(envhub_hub::env_vars::ENVHUB_SESSION_CIPHER)
        .stdin(std::process::Stdio::null());
    if let Some(c) = cipher {
        cmd.env(envhub_hub::env_vars::ENVHUB_SESSION_CIPHER, c);
    }
    let out = cmd.output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn sessions_sealed_with_either_cipher_run_the_same_rollout_and_a_bad_name_is_refused() {
    let a = RemoteHub::start("ciphers", &[], &[]);
    let mut rollouts = Vec::new();
    for cipher in [None, Some("aes-256-gcm"), Some("chacha20-poly1305")] {
        let (code, out, err) = run_remote(&a, cipher);
        assert_eq!(code, 0, "{cipher:?}: {err}");
        let v: serde_json::Value = serde_json::from_str(out.trim()).expect("--json output");
        assert_eq!(v["steps"], 400, "{cipher:?}: {v}");
        rollouts.push((cipher, v["episodes"].clone(), v["mean_return"].clone()));
    }
    // The same seeds give the same episodes whatever seals them.
    for r in &rollouts[1..] {
        assert_eq!(
            (&r.1, &r.2),
            (&rollouts[0].1, &rollouts[0].2),
            "{rollouts:?}"
        );
    }
    let (code, _, err) = run_remote(&a, Some("rot13"));
    assert_ne!(code, 0);
    assert!(
        err.contains("ENVHUB_SESSION_CIPHER")
            && err.contains("rot13")
            && err.contains("aes-256-gcm, chacha20-poly1305"),
        "{err}"
    );
}
