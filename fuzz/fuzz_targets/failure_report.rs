//! A worker's or a hub's report of envs that failed (`read_failure_report`, JSON): a report
//! that passes names only envs that were sent, each at most once per entry it lists. The
//! first byte picks the worker's offset and the envs it was sent.
#![no_main]

use envhub_protocol::untrusted::read_failure_report;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, msg)) = data.split_first() else {
        return;
    };
    // The high nibble: the worker's first env; the low one: which of its 4 envs were sent.
    let offset = usize::from(pick >> 4);
    let sent: Vec<usize> = (0..4)
        .filter(|i| pick & (1 << i) != 0)
        .map(|i| offset + i)
        .collect();
    if let Ok(report) = read_failure_report(msg, "worker 0", &sent, offset) {
        assert!(report.failed.len() <= sent.len());
        for (k, _) in &report.failed {
            assert!(
                sent.contains(&(offset + k)),
                "env {k} passed, which was not sent"
            );
        }
    }
});
