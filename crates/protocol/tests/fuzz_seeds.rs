//! The seed corpora of the cargo-fuzz targets (`fuzz/corpus/<target>/seed-*`): real messages,
//! made by the same encoders the processes use, so the fuzzer starts from inputs that reach
//! past the first check of each parser.
//!
//! This test checks that every seed it makes is read by its parser. With
//! `ENVHUB_WRITE_FUZZ_SEEDS=1` it also writes them (run it so after a message changes):
//! `ENVHUB_WRITE_FUZZ_SEEDS=1 cargo test -p envhub-protocol --test fuzz_seeds`.

use envhub_core::{EnvConfig, ResetOptions, Space};
use envhub_protocol::batch_codec::{self, RemoteAnswer, RequestBody, RowsOut};
use envhub_protocol::daemon::{self, Request, UserAdapters};
use envhub_protocol::info_columns::InfoSchema;
use envhub_protocol::untrusted::{check_open_reply, read_failure_report};
use envhub_protocol::{HubError, HubInfo, OpenReply, OpenRequest, Route};
use envhub_shm::{
    BatchLayout, ChannelName, Layout, ReadySpec, SlotsName, WorkerJob, WorkerReply, command,
};
use serde_json::json;
use std::path::PathBuf;
use std::time::Duration;

/// The first byte of inputs whose targets read bytes against a layout: the fuzz crate's
/// `layouts(0)` (3 envs, 4 action bytes, 16 observation bytes, no final observations).
const PICK: u8 = 0;

fn layouts() -> (Layout, BatchLayout) {
    (Layout::new(3, 4), BatchLayout::new(3, 16, false))
}

fn picked(bytes: Vec<u8>) -> Vec<u8> {
    let mut out = vec![PICK];
    out.extend(bytes);
    out
}

fn json(value: impl serde::Serialize) -> Vec<u8> {
    serde_json::to_vec(&value).expect("serializes")
}

fn cartpole_spec() -> ReadySpec {
    ReadySpec {
        observation_space: Space::box_f32(&[4], -4.8, 4.8),
        action_space: Space::discrete(2),
        max_episode_steps: Some(500),
        render_fps: Some(50.0),
        pid: 4242,
        worker: None,
    }
}

fn nested_spec() -> ReadySpec {
    let observation_space: Space = serde_json::from_value(json!({
        "type": "dict",
        "spaces": [
            ["pos", {"type": "box", "dtype": "float64", "shape": [2], "low": [-1.0, -1.0], "high": [1.0, 1.0]}],
            ["grip", {"type": "multi_binary", "shape": [3]}],
            ["mode", {"type": "tuple", "spaces": [{"type": "discrete", "n": 3, "start": 0}]}]
        ]
    }))
    .expect("a dict space");
    ReadySpec {
        observation_space,
        action_space: serde_json::from_value(
            json!({"type": "multi_discrete", "nvec": [2, 3], "start": [0, 0]}),
        )
        .expect("a multi-discrete space"),
        max_episode_steps: None,
        render_fps: None,
        pid: 7,
        worker: None,
    }
}

fn route() -> Route {
    let mut config = EnvConfig {
        num_envs: 4,
        seed: Some(1),
        ..EnvConfig::default()
    };
    config.extra.insert("gravity".into(), json!(9.81));
    Route {
        adapter: "classic_control".into(),
        env_id: "CartPole-v1".into(),
        config,
        python: None,
    }
}

fn job() -> WorkerJob {
    WorkerJob {
        adapter: "classic_control".into(),
        env_id: "CartPole-v1".into(),
        config: route().config,
        env_offset: 2,
        worker_envs: 2,
        session_envs: 4,
        channel: ChannelName {
            prefix: "envhub_1234_".into(),
            service: "envhub/1234-0-abc/1/0".into(),
        },
        slots: SlotsName::new("envhub_1234_", "1234-0-abc"),
        worker_index: 1,
        session_workers: 2,
        owner_pid: 1234,
        spin_us: 50,
        max_spin_us: 200,
        info_row_bytes: 0,
        python: None,
    }
}

fn errors() -> Vec<HubError> {
    vec![
        HubError::InvalidConfig {
            what: "reset options",
            reason: "expected a map".into(),
        },
        HubError::WorkerDied {
            worker: 0,
            envs: "0..2".into(),
            pid: 77,
            why: "died (signal: 9 (SIGKILL))".into(),
        },
        HubError::EnvFailed {
            worker: 1,
            envs: vec![2],
            message: "boom".into(),
        },
        HubError::Refused {
            hub: "box1".into(),
            reason: "full".into(),
            hint: "try later".into(),
        },
        HubError::Interrupted,
    ]
}

/// Every seed: (target, file name, bytes).
fn seeds() -> Vec<(&'static str, String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut add = |target: &'static str, name: &str, bytes: Vec<u8>| {
        out.push((target, format!("seed-{name}"), bytes));
    };
    let (requests, rows) = layouts();
    let actions: Vec<u8> = (0..12).collect();
    let reset = RequestBody {
        actions: None,
        selected: Some(&[true, false, true]),
        seeds: &[Some(1), None, Some(u64::MAX)],
        options: br#"{"qpos": [0.1, -0.2], "difficulty": 2}"#,
    };
    add(
        "wire_request",
        "reset",
        picked(batch_codec::encode_request(
            &requests,
            1,
            command::RESET,
            0,
            &reset,
        )),
    );
    let step = RequestBody {
        actions: Some(&actions),
        ..RequestBody::NONE
    };
    add(
        "wire_request",
        "step",
        picked(batch_codec::encode_request(
            &requests,
            2,
            command::STEP,
            1,
            &step,
        )),
    );
    add(
        "wire_request",
        "close",
        picked(batch_codec::encode_request(
            &requests,
            3,
            command::CLOSE,
            0,
            &RequestBody::NONE,
        )),
    );

    let mut block = vec![0u8; rows.size()];
    let obs: Vec<u8> = (0..48).collect();
    batch_codec::write_rows(
        &rows,
        &mut block,
        &[0, 1, 2],
        &RowsOut {
            obs: &obs,
            rewards: &[1.0, 0.5, -1.0],
            terminated: &[false, true, false],
            truncated: &[false, false, true],
            final_mask: &[],
            final_obs: &[],
        },
    );
    let infos = br#"[{"x_threshold": 2.4}, {"TimeLimit.truncated": false}, {}]"#;
    add(
        "wire_response",
        "step",
        picked(batch_codec::encode_response(2, 0, 3, &block, infos)),
    );
    let frames = envhub_shm::frames_section([
        Some((2, 2, vec![200u8; 12])),
        None,
        Some((1, 1, vec![1, 2, 3])),
    ]);
    add(
        "wire_response",
        "render",
        picked(batch_codec::encode_response(4, 0, 3, &[], &frames)),
    );
    let failed = json(json!({"failed": [[1, "boom"]], "info": [{}, null, {}]}));
    add(
        "wire_response",
        "env_failed",
        picked(batch_codec::encode_response(
            5,
            envhub_shm::status::ENV_FAILED,
            3,
            &block,
            &failed,
        )),
    );
    add(
        "wire_response",
        "hub_error",
        picked(batch_codec::encode_error(6, 3, &errors()[1])),
    );
    add("frames", "render", frames);

    let request = OpenRequest {
        id: "gym-cartpole".into(),
        config: route().config,
        client: "envhub/client/1234-0-abc".into(),
        restart_on_crash: true,
        step_timeout_ms: 30_000,
    };
    let identity = envhub_protocol::handshake::Identity::generate().expect("an identity");
    let (hello, _) = envhub_protocol::handshake::client_hello(
        &identity,
        "box1",
        1_800_000_000_000,
        &envhub_protocol::seal::Cipher::ALL,
    )
    .expect("a hello");
    add(
        "open_request",
        "cartpole",
        json(envhub_protocol::OpenMessage { request, hello }),
    );
    for (name, spec) in [("cartpole", cartpole_spec()), ("nested", nested_spec())] {
        let reply = OpenReply {
            session: "1234-0-abc".into(),
            spec,
            route: route(),
            workers: 2,
            hello: envhub_protocol::handshake::HubHello {
                exchange: "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff".into(),
                identity: "ffeeddccbbaa99887766554433221100ffeeddccbbaa99887766554433221100".into(),
                proof: "ab".repeat(64),
                cipher: Some("aes-256-gcm".into()),
            },
        };
        add("open_reply", name, picked(json(&reply)));
    }
    let options: ResetOptions = serde_json::from_value(
        json!({"qpos": [0.1, -0.2], "difficulty": 2, "task": {"name": "reach", "goal": null}}),
    )
    .expect("options");
    add("reset_options", "qpos", json(&options));
    add(
        "info_schema",
        "two_keys",
        br#"{"id": 9, "keys": [{"key": "x", "dtype": "<f8", "shape": [], "offset": 8, "mask": 40, "kind": "py"}, {"key": "v", "dtype": "<f4", "shape": [2, 3], "offset": 16, "mask": 41, "kind": "array"}]}"#.to_vec(),
    );
    let info = HubInfo {
        name: "box1".into(),
        host: "box1.lab".into(),
        cores: 16,
        version: "0.1.0".into(),
        adapters: vec!["classic_control".into(), "mujoco".into()],
        catalog: 120,
        envs: 8,
        workers: 2,
        sessions: 1,
        load: 0.75,
        max_envs: Some(256),
        max_workers: None,
    };
    add("hub_info", "info", {
        let mut b = vec![0u8];
        b.extend(json(&info));
        b
    });
    let registry = envhub_catalog::Registry::builtin();
    add("hub_info", "catalog", {
        let mut b = vec![1u8];
        b.extend(json(&registry.entries()[..registry.len().min(3)]));
        b
    });
    for (k, e) in errors().iter().enumerate() {
        add("hub_error", &format!("error{k}"), json(e));
    }
    add("failure_report", "one", {
        // A worker whose envs start at 1 (high nibble), sent its first two (low nibble).
        let mut b = vec![0x13];
        b.extend(json(json!({"failed": [[0, "boom"]], "info": [{"a": 1}]})));
        b
    });
    add(
        "ready_line",
        "cartpole",
        json(WorkerReply::Ready(cartpole_spec())),
    );
    add(
        "ready_line",
        "nested",
        json(WorkerReply::Ready(nested_spec())),
    );
    add(
        "ready_line",
        "error",
        json(WorkerReply::Error(
            "no module named `gymnasium`\nhint: pip install gymnasium".into(),
        )),
    );
    add("route", "cartpole", json(route()));
    add("worker_job", "cartpole", json(job()));
    let user = UserAdapters {
        adapters: vec!["my_pkg.envs:MyAdapter".into()],
        pythonpath: vec![PathBuf::from("/home/me/src")],
    };
    let requests = [
        Request::Ping,
        Request::Status,
        Request::Adapters { user: user.clone() },
        Request::Route {
            id: "gym-cartpole".into(),
            config: route().config,
            user: user.clone(),
        },
        Request::Launch {
            job: Box::new(job()),
            start_timeout: Duration::from_secs(60),
            user,
        },
        Request::ExitStatus { pid: 4242 },
    ];
    let lines: String = requests.iter().map(|r| r.encode() + "\n").collect();
    add("daemon_request", "session", lines.into_bytes());
    add(
        "daemon_reply",
        "ok_spec",
        daemon::encode_reply(&Ok(serde_json::to_value(cartpole_spec()).unwrap())).into_bytes(),
    );
    add(
        "daemon_reply",
        "ok_route",
        daemon::encode_reply(&Ok(serde_json::to_value(route()).unwrap())).into_bytes(),
    );
    add(
        "daemon_reply",
        "error",
        daemon::encode_reply(&Err(errors().remove(1))).into_bytes(),
    );
    out
}

/// What each target's parser makes of its seed: it must accept it.
fn accepted(target: &str, bytes: &[u8]) -> Result<(), String> {
    let (requests, rows) = layouts();
    let body = bytes.get(1..).unwrap_or_default();
    let ok = |r: Result<(), String>| r;
    match target {
        "wire_request" => batch_codec::parse_request(body, &requests).map(drop),
        "wire_response" => RemoteAnswer::parse(body.to_vec())
            .filter(|a| a.rows().is_empty() || a.rows().len() == rows.size())
            .map(drop)
            .ok_or_else(|| "unparsed".into()),
        "frames" => envhub_protocol::Frame::parse(bytes)
            .map(drop)
            .ok_or_else(|| "unparsed".into()),
        "open_request" => envhub_protocol::untrusted::read_open_request(bytes).map(drop),
        "open_reply" => {
            let reply: OpenReply = serde_json::from_slice(body).map_err(|e| e.to_string())?;
            check_open_reply("seed", &reply, 1, false)
                .map(drop)
                .map_err(|e| e.to_string())
        }
        "reset_options" => serde_json::from_slice::<ResetOptions>(bytes)
            .map(drop)
            .map_err(|e| e.to_string()),
        "info_schema" => InfoSchema::parse(std::str::from_utf8(bytes).unwrap(), 48).map(drop),
        "hub_info" if bytes[0] == 0 => serde_json::from_slice::<HubInfo>(body)
            .map(drop)
            .map_err(|e| e.to_string()),
        "hub_info" => serde_json::from_slice::<Vec<envhub_catalog::EnvEntry>>(body)
            .map(drop)
            .map_err(|e| e.to_string()),
        "hub_error" => serde_json::from_slice::<HubError>(bytes)
            .map(drop)
            .map_err(|e| e.to_string()),
        "failure_report" => read_failure_report(body, "seed", &[1, 2], 1).map(drop),
        "ready_line" => serde_json::from_slice::<WorkerReply>(bytes)
            .map(drop)
            .map_err(|e| e.to_string()),
        "route" => serde_json::from_slice::<Route>(bytes)
            .map(drop)
            .map_err(|e| e.to_string()),
        "worker_job" => serde_json::from_slice::<WorkerJob>(bytes)
            .map(drop)
            .map_err(|e| e.to_string()),
        "daemon_request" => std::str::from_utf8(bytes)
            .unwrap()
            .lines()
            .try_for_each(|l| Request::parse(l).map(drop).map_err(|e| e.to_string())),
        "daemon_reply" => match daemon::parse_reply(std::str::from_utf8(bytes).unwrap()) {
            Ok(_) | Err(daemon::ReplyError::Error(_)) => Ok(()),
            Err(e) => Err(format!("{e:?}")),
        },
        other => ok(Err(format!("no parser for target `{other}`"))),
    }
}

#[test]
fn every_seed_is_a_message_its_parser_reads() {
    let corpus = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus");
    let write = std::env::var_os("ENVHUB_WRITE_FUZZ_SEEDS").is_some();
    for (target, name, bytes) in seeds() {
        accepted(target, &bytes).unwrap_or_else(|e| panic!("{target}/{name}: {e}"));
        assert!(bytes.len() < 8192, "{target}/{name}: seeds stay small");
        if write {
            let dir = corpus.join(target);
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join(&name), &bytes).unwrap();
        }
    }
}
