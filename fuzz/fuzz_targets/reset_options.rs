//! Reset options (`ResetOptions`: a JSON object), as a hub reads them from a remote
//! request's option bytes and a worker from its channel: any UTF-8 parses or is refused,
//! and options a client encodes read back as sent.
#![no_main]

use envhub_core::ResetOptions;
use envhub_fuzz::assert_json_round_trip;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The hub and the worker take the option bytes as UTF-8 text first.
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(options) = serde_json::from_str::<ResetOptions>(text) {
        assert_json_round_trip(&options);
    }
});
