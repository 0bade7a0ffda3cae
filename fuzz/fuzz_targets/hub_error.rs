//! An error another process sends (`HubError`, JSON: a hub's `HUB_ERROR` response, a
//! daemon's or a hub's reply), as a client takes it (`from_hub`): never as a kind that
//! describes this process (`Interrupted` is raised as `KeyboardInterrupt`); its text
//! renders; it reads back as sent.
#![no_main]

use envhub_fuzz::assert_json_round_trip;
use envhub_protocol::HubError;
use envhub_protocol::batch_codec::decode_error;
use envhub_protocol::untrusted::from_hub;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(e) = serde_json::from_slice::<HubError>(data) {
        assert_json_round_trip(&e);
        let _ = e.to_string();
    }
    let taken = from_hub("fuzz", decode_error("fuzz", data));
    assert!(
        !matches!(
            taken,
            HubError::Interrupted | HubError::HubLost { .. } | HubError::Daemon { .. }
        ),
        "a hub's error passed as {taken:?}"
    );
    let _ = taken.to_string();
});
