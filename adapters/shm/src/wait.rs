//! Waiting for the next sample without burning a core.
//!
//! The loop is "try to receive; if nothing, block on the listener for at most one tick;
//! repeat". A notification sent before the wait begins is not lost (iceoryx2 queues it), and
//! a stale one costs one empty round, so no sample is missed and no wake-up is needed twice.
//! Between ticks the caller's liveness check runs, which is how a dead or hung peer is
//! noticed while waiting.

use crate::DataPlaneError;
use crate::transport::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ZeroCopySend;
use iceoryx2::sample::Sample;
use std::time::{Duration, Instant};

/// How long to spin on `receive` before blocking. A short spin saves the wake-up latency when
/// the answer is microseconds away (a cheap env); blocking keeps a 2-core machine usable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WaitPolicy {
    /// Spin this long before blocking.
    pub spin: Duration,
    /// Check liveness at least this often while blocked.
    pub tick: Duration,
}

impl Default for WaitPolicy {
    fn default() -> Self {
        WaitPolicy {
            spin: Duration::from_micros(20),
            tick: Duration::from_millis(20),
        }
    }
}

/// Receives the next sample, calling `alive` every `policy.tick` while none arrives. An error
/// from `alive` ends the wait with that error.
pub(crate) fn next_sample<H: std::fmt::Debug + ZeroCopySend>(
    subscriber: &Subscriber<Ipc, [u8], H>,
    listener: &Listener<Ipc>,
    policy: WaitPolicy,
    mut alive: impl FnMut() -> Result<(), DataPlaneError>,
) -> Result<Sample<Ipc, [u8], H>, DataPlaneError> {
    let receive = || {
        subscriber.receive().map_err(|e| DataPlaneError::Ipc {
            what: "receive",
            detail: format!("{e:?}"),
        })
    };
    if !policy.spin.is_zero() {
        let start = Instant::now();
        loop {
            if let Some(sample) = receive()? {
                return Ok(sample);
            }
            if start.elapsed() >= policy.spin {
                break;
            }
            // Yield rather than spin: when the peer shares this core, a plain spin would keep
            // it from running at all until the time slice ends (tens of microseconds).
            std::thread::yield_now();
        }
    }
    let mut next_check = Instant::now() + policy.tick;
    loop {
        if let Some(sample) = receive()? {
            return Ok(sample);
        }
        let timeout = next_check.saturating_duration_since(Instant::now());
        listener
            .timed_wait(|_| {}, timeout)
            .map_err(|e| DataPlaneError::Ipc {
                what: "wait",
                detail: format!("{e:?}"),
            })?;
        if Instant::now() >= next_check {
            alive()?;
            next_check = Instant::now() + policy.tick;
        }
    }
}
