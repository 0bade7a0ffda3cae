//! What a peer that is not supposed to reach a hub can see of it: its links, the envhub
//! tokens it is shown, and the answers to an `open` it sends in the hub's name.

use std::time::Duration;
use zenoh::Wait;

/// What `peer` got from hub `hub`.
pub struct Seen {
    /// The Zenoh ids of the peers it is linked to.
    pub peers: Vec<String>,
    /// The keys of the envhub liveliness tokens it sees (an error reply counts, as
    /// `<error reply>`: something answered).
    pub tokens: Vec<String>,
    /// The answers to a `gym-cartpole` open it asked of the hub.
    pub open_answers: usize,
}

/// Asks, as `peer`, for every envhub token and for a session on hub `hub`.
pub fn probe(peer: &zenoh::Session, hub: &str) -> Seen {
    let tokens = peer
        .liveliness()
        .get("envhub/**")
        .timeout(Duration::from_secs(1))
        .wait()
        .unwrap()
        .iter()
        .map(|r| {
            r.result()
                .map_or("<error reply>".to_string(), |s| s.key_expr().to_string())
        })
        .collect();
    let open_answers = peer
        .get(format!("envhub/hub/{hub}/open"))
        .payload(
            serde_json::json!({
                "id": "gym-cartpole", "config": {"num_envs": 1}, "client": "envhub/client/x",
                "restart_on_crash": false, "step_timeout_ms": 1000
            })
            .to_string(),
        )
        .timeout(Duration::from_secs(2))
        .wait()
        .unwrap()
        .iter()
        .count();
    let peers = peer
        .info()
        .peers_zid()
        .wait()
        .map(|z| z.to_string())
        .collect();
    Seen {
        peers,
        tokens,
        open_answers,
    }
}

/// A well-formed answer to a `gym-cartpole` open, as a fake hub gives it: session `session`,
/// observation space `observation_space`, its half of the key exchange `hello`
/// (`envhub_protocol::handshake::HubHello`).
pub fn cartpole_open_reply(
    session: &str,
    observation_space: serde_json::Value,
    hello: serde_json::Value,
) -> serde_json::Value {
    serde_json::json!({"ok": {
        "session": session,
        "spec": {
            "observation_space": observation_space,
            "action_space": {"type": "discrete", "n": 2, "start": 0},
            "max_episode_steps": 500,
            "pid": 1,
        },
        "route": {"adapter": "classic_control", "env_id": "CartPole-v1", "config": {}},
        "workers": 1,
        "hello": hello,
    }})
}
