//! A worker's job (`WorkerJob`, JSON), as a worker process reads it from the process that
//! starts it (`envhub-worker serve --job`, or the daemon's `launch` request): parse or
//! refuse, read back as sent.
#![no_main]

use envhub_fuzz::assert_json_round_trip;
use envhub_shm::WorkerJob;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(job) = serde_json::from_slice::<WorkerJob>(data) {
        assert_json_round_trip(&job);
    }
});
