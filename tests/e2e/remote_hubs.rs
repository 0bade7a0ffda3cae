//! Hubs across machines, simulated on loopback: several `envhub serve` processes, each with its
//! own iceoryx2 namespace, multicast off and explicit endpoints; real Zenoh sessions.

use envhub::{EnvConfig, Hub, HubError, Placement};
use envhub_e2e::remote::{RemoteHub, client, net_to};
use envhub_e2e::{TestHub, mujoco_available, sigkill};
use rand::SeedableRng;
use std::time::{Duration, Instant};

fn hubs(names: &[&RemoteHub]) -> Placement {
    Placement::Hubs(names.iter().map(|h| h.name.clone()).collect())
}

/// Steps `remote` and `local` (same id, config, seeds, actions) side by side and asserts
/// every result is equal bit for bit.
fn assert_same_rollout(remote: &mut envhub::VecEnv, local: &mut envhub::VecEnv, steps: usize) {
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
fn expect_lost(env: &mut envhub::VecEnv, hub: &str, since: Instant, limit: Duration) {
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
        .env(envhub::ENVHUB_MULTICAST, "0")
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

#[test]
fn garbage_on_session_keys_is_answered_and_the_session_goes_on() {
    use zenoh::Wait;
    let a = RemoteHub::start("ga", &[], &[]);
    // Another peer on the network: the client connects to it too, so it sees the session's
    // requests (peers do not route for each other) and can put its own on the session's key.
    let spy_endpoint = format!("tcp/127.0.0.1:{}", envhub_e2e::remote::free_port());
    let mut spy_net = net_to(&[&a]);
    spy_net.listen = vec![spy_endpoint.clone()];
    let spy = zenoh::open(spy_net.zenoh_config(false).unwrap())
        .wait()
        .unwrap();
    let mut net = net_to(&[&a]);
    net.connect.push(spy_endpoint);
    let hub = Hub::new(envhub::Registry::builtin()).with_network(net);
    let (tx, rx) = std::sync::mpsc::channel();
    let _requests = spy
        .declare_subscriber("envhub/session/ga/*/req")
        .callback(move |s| {
            let _ = tx.send(s.key_expr().as_str().to_string());
        })
        .wait()
        .unwrap();
    let (atx, arx) = std::sync::mpsc::channel();
    let _answers = spy
        .declare_subscriber("envhub/session/ga/*/rep")
        .callback(move |s| {
            let _ = atx.send(s.payload().to_bytes().into_owned());
        })
        .wait()
        .unwrap();
    let mut env = hub
        .make_vec_on("gym-cartpole", 2, &EnvConfig::default(), &hubs(&[&a]))
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    env.reset(Some(1)).unwrap();
    for _ in 0..10 {
        env.step(&[0u8; 16]).unwrap();
    }
    // One message per hub and round trip: the reset and ten steps.
    let keys: Vec<String> = rx.try_iter().collect();
    assert_eq!(keys.len(), 11, "requests seen: {keys:?}");
    let session_key = keys[0].clone();
    let _ = arx.try_iter().count();
    // Random bytes, a header with a wrong size, an unknown session: each answered with an
    // error, none stepping anything.
    let mut junk: Vec<Vec<u8>> = vec![vec![7u8; 5], vec![0xff; 100]];
    let mut header = vec![0u8; 24];
    header[0] = 200; // seq
    header[8] = 2; // step
    header[12] = 9; // 9 envs (the session has 2)
    junk.push(header);
    for bytes in &junk {
        spy.put(&session_key, bytes.clone()).wait().unwrap();
    }
    spy.put("envhub/session/ga/nosuchsession/req", vec![1u8; 40])
        .wait()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut errors = 0;
    while errors < junk.len() + 1 && Instant::now() < deadline {
        if let Ok(answer) = arx.recv_timeout(Duration::from_millis(100)) {
            let status = u32::from_le_bytes(answer[8..12].try_into().unwrap());
            assert_eq!(
                status,
                envhub_shm::status::ERROR,
                "garbage answered with {status}"
            );
            errors += 1;
        }
    }
    assert_eq!(errors, junk.len() + 1, "every piece of garbage is answered");
    // The session and the hub go on.
    for _ in 0..10 {
        env.step(bytemuck::cast_slice(&[1i64, 1])).unwrap();
    }
    let mut other = hub
        .make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &hubs(&[&a]))
        .unwrap();
    other.reset(None).unwrap();
}

fn expect_refused(result: Result<envhub::VecEnv, HubError>, needle: &str) {
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
    let a = RemoteHub::start("sa", &["--max-envs", "4", "--max-workers", "2"], &[]);
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
        Hub::new(envhub::Registry::builtin()).with_network(net)
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
    let options = envhub::SessionOptions {
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
