//! What a remote hub answers to `info` (`HubInfo`) and `catalog` (its registry entries,
//! `Vec<EnvEntry>`), as a client reads them: parse or refuse, and read back as sent. The
//! first byte picks which.
#![no_main]

use envhub_catalog::EnvEntry;
use envhub_fuzz::assert_json_round_trip;
use envhub_protocol::HubInfo;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, msg)) = data.split_first() else {
        return;
    };
    if pick % 2 == 0 {
        if let Ok(info) = serde_json::from_slice::<HubInfo>(msg) {
            let back: HubInfo =
                serde_json::from_str(&serde_json::to_string(&info).expect("serializes"))
                    .expect("its own encoding parses");
            assert_eq!(back, info);
        }
    } else if let Ok(entries) = serde_json::from_slice::<Vec<EnvEntry>>(msg) {
        assert_json_round_trip(&entries);
    }
});
