//! A hub's reply to an open request (`OpenReply`, JSON), as the client checks it
//! (`check_open_reply`) before it lays out memory by its spaces: a reply that passes gives
//! layouts whose sizes are the spaces' own, and spaces that may be used. The first byte
//! picks the envs asked for (up to far more than memory holds).
#![no_main]

use envhub_fuzz::assert_json_round_trip;
use envhub_protocol::OpenReply;
use envhub_protocol::untrusted::check_open_reply;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, msg)) = data.split_first() else {
        return;
    };
    let Ok(reply) = serde_json::from_slice::<OpenReply>(msg) else {
        return;
    };
    assert_json_round_trip(&reply);
    let n = [1, 4, 1 << 20, usize::MAX / 4][usize::from(pick % 4)];
    if let Ok((requests, rows)) = check_open_reply("fuzz", &reply, n, pick & 4 != 0) {
        let spec = &reply.spec;
        let obs = spec.observation_space.byte_len();
        assert_eq!(rows.obs_bytes, obs);
        assert_eq!(requests.act_bytes, spec.action_space.byte_len());
        let _ = spec.observation_space.leaves();
        let _ = spec.action_space.leaves();
        if obs <= 1 << 16 {
            let _ = spec.observation_space.validate(&vec![0u8; obs]);
        }
        let _ = spec.observation_space.to_string();
    }
});
