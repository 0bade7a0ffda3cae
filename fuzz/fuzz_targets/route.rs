//! A route (`Route`: adapter, env id, complete config, Python environment), as a client reads
//! it in a daemon's `route` reply or a hub's open reply: parse or refuse, read back as sent.
#![no_main]

use envhub_protocol::Route;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(route) = serde_json::from_slice::<Route>(data) {
        let text = serde_json::to_string(&route).expect("routes serialize");
        let back: Route = serde_json::from_str(&text).expect("its own encoding parses");
        assert_eq!(back, route);
    }
});
