//! The one line a worker prints when it starts (`WorkerReply`: its spec, or why it could not
//! start), as the process that started it reads it (directly, or through the daemon's
//! `launch` reply). Spaces that pass their check give layouts whose sizes are the spaces'
//! own; the line reads back as sent.
#![no_main]

use envhub_fuzz::assert_json_round_trip;
use envhub_shm::{BatchLayout, Layout, WorkerReply};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(line) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(reply) = serde_json::from_str::<WorkerReply>(line) else {
        return;
    };
    assert_json_round_trip(&reply);
    let WorkerReply::Ready(spec) = reply else {
        return;
    };
    for num_envs in [1usize, 64, usize::MAX / 8] {
        if let Ok(obs) = spec.observation_space.check()
            && let Some(rows) = BatchLayout::checked(num_envs, obs, true)
        {
            assert_eq!(rows.obs_bytes, spec.observation_space.byte_len());
            let _ = rows.with_info_columns(64);
        }
        if let Ok(act) = spec.action_space.check()
            && let Some(requests) = Layout::checked(num_envs, act)
        {
            assert_eq!(requests.act_bytes, spec.action_space.byte_len());
        }
    }
    if spec.observation_space.check().is_ok() {
        let _ = spec.observation_space.leaves();
        let _ = spec.observation_space.to_string();
    }
});
