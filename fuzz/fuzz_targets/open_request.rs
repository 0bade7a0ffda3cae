//! A request to open a session (`OpenMessage`: the `OpenRequest` and the client's hello, JSON),
//! as a hub reads it from any client (`read_open_request`: its length, nesting and number of
//! values bounded before it is parsed): it parses or is refused, never panics nor allocates
//! beyond those bounds (inputs run one byte past the longest it reads: `scripts/fuzz.sh`), and
//! what a client encodes reads back as sent. The config's typed accessors (what adapters read
//! from it) take any value it holds.
#![no_main]

use envhub_fuzz::assert_json_round_trip;
use envhub_protocol::untrusted::read_open_request;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(message) = read_open_request(data) else {
        return;
    };
    assert_json_round_trip(&message);
    let _ = envhub_protocol::handshake::check_client_hello("fuzz", &message.hello, 0);
    let config = &message.request.config;
    let _ = config.action_bounds();
    let _ = config.episode_limit(Some(500));
    let _ = envhub_protocol::untrusted::check_remote_kwargs(&config.extra);
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
