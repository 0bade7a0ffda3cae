//! A request to open a session (`OpenRequest`, JSON), as a hub reads it from any client: it
//! parses or is refused, never panics, and what a client encodes reads back as sent. The
//! config's typed accessors (what adapters read from it) take any value it holds.
#![no_main]

use envhub_fuzz::assert_json_round_trip;
use envhub_protocol::OpenRequest;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(request) = serde_json::from_slice::<OpenRequest>(data) else {
        return;
    };
    assert_json_round_trip(&request);
    let config = &request.config;
    let _ = config.action_bounds();
    let _ = config.episode_limit(Some(500));
    let known: Vec<&str> = config.extra.keys().map(String::as_str).collect();
    let _ = config.extra_keys("Fuzz-v0", &known[..known.len() / 2]);
    let keys = config
        .extra_keys("Fuzz-v0", &known)
        .expect("every key is known");
    for key in &known {
        let _ = keys.f64(key, 0.0);
        let _ = keys.bool(key, false);
        let _ = keys.u64(key, 0);
        let _ = keys.str(key);
        let _ = keys.range(key, (0.0, 1.0));
    }
});
