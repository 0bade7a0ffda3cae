//! Waiting for the next sample without burning a core.
//!
//! The loop is "try to receive; if nothing, block on the listener for at most one tick;
//! repeat". A notification sent before the wait begins is not lost (iceoryx2 queues it), and
//! a stale one costs one empty round, so no sample is missed and no wake-up is needed twice.
//! Between ticks the caller's liveness check runs, which is how a dead or hung peer is
//! noticed while waiting.

use crate::DataPlaneError;
use crate::transport::Ipc;
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ZeroCopySend;
use iceoryx2::sample::Sample;
use std::sync::atomic::{AtomicU32, Ordering, fence};
use std::time::{Duration, Instant};

/// How long to spin on `receive` before blocking. Spinning saves the wake-up latency (tens of
/// µs on a VM) when the answer is close; blocking keeps a long wait free. The spin adapts:
/// it covers the usual wait (a smoothed average of recent waits, plus a margin) within
/// `[spin, max_spin]`, so a MuJoCo step of a millisecond is caught spinning while an idle
/// worker soon blocks. Spinning yields the core every round, so a process that needs the
/// core gets it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WaitPolicy {
    /// Always spin at least this long before blocking (0: never spin).
    pub spin: Duration,
    /// Never spin longer than this.
    pub max_spin: Duration,
    /// Check liveness at least this often while blocked.
    pub tick: Duration,
    /// When recent waits average longer than this, block at once instead of spinning (zero:
    /// never). A client with as many workers as cores sets it: spinning, even yielding, would
    /// take CPU time from the workers it waits for, and a wait that long pays for a wake-up.
    pub block_beyond: Duration,
}

impl Default for WaitPolicy {
    fn default() -> Self {
        WaitPolicy {
            spin: Duration::from_micros(50),
            max_spin: Duration::from_millis(2),
            tick: Duration::from_millis(20),
            block_beyond: Duration::ZERO,
        }
    }
}

/// The smoothed length of recent waits, which sets the next spin budget.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct AdaptiveSpin {
    average_ns: f64,
}

impl AdaptiveSpin {
    /// The spin budget for the next wait under `policy`.
    pub fn budget(&self, policy: &WaitPolicy) -> Duration {
        if policy.spin.is_zero() {
            return Duration::ZERO;
        }
        if !policy.block_beyond.is_zero() && self.average_ns > policy.block_beyond.as_nanos() as f64
        {
            return Duration::ZERO;
        }
        let wanted = Duration::from_nanos((self.average_ns * 1.5) as u64);
        wanted.clamp(policy.spin, policy.max_spin.max(policy.spin))
    }

    /// Records how long a wait took.
    pub fn observe(&mut self, waited: Duration) {
        const WEIGHT: f64 = 0.2;
        let ns = waited.as_nanos() as f64;
        self.average_ns = if self.average_ns == 0.0 {
            ns
        } else {
            self.average_ns + WEIGHT * (ns - self.average_ns)
        };
    }
}

/// Raises a "blocked" flag for as long as it lives, so the peer notifies (see [`ring`]).
pub(crate) struct Blocked<'a>(Option<&'a AtomicU32>);

impl<'a> Blocked<'a> {
    /// Raises `flag` (if any). The fence orders the raise before the caller's next look at
    /// its queue, so a peer that published before seeing the flag is seen by that look.
    pub fn raise(flag: Option<&'a AtomicU32>) -> Blocked<'a> {
        if let Some(f) = flag {
            f.store(1, Ordering::SeqCst);
            fence(Ordering::SeqCst);
        }
        Blocked(flag)
    }
}

impl Drop for Blocked<'_> {
    fn drop(&mut self) {
        if let Some(f) = self.0 {
            f.store(0, Ordering::SeqCst);
        }
    }
}

/// Notifies the peer after a publish, unless its flag says it is not blocked (it is spinning
/// and will see the sample without a wake-up). No flag: always notify. A notification missed
/// through a race costs at most one tick: a blocked side looks at its queue every tick.
pub(crate) fn ring(
    notifier: &iceoryx2::port::notifier::Notifier<Ipc>,
    peer_blocked: Option<&AtomicU32>,
) -> Result<(), DataPlaneError> {
    fence(Ordering::SeqCst);
    if peer_blocked.is_none_or(|f| f.load(Ordering::SeqCst) != 0) {
        notifier.notify().map_err(|e| DataPlaneError::Ipc {
            what: "notify",
            detail: format!("{e:?}"),
        })?;
    }
    Ok(())
}

/// Receives the next sample, calling `alive` every `policy.tick` while none arrives. An error
/// from `alive` ends the wait with that error. `blocked` is this side's flag, raised while it
/// blocks (see [`ring`]).
pub(crate) fn next_sample<H: std::fmt::Debug + ZeroCopySend>(
    subscriber: &Subscriber<Ipc, [u8], H>,
    listener: &Listener<Ipc>,
    spin: Duration,
    tick: Duration,
    blocked: Option<&AtomicU32>,
    mut alive: impl FnMut() -> Result<(), DataPlaneError>,
) -> Result<Sample<Ipc, [u8], H>, DataPlaneError> {
    let receive = || {
        subscriber.receive().map_err(|e| DataPlaneError::Ipc {
            what: "receive",
            detail: format!("{e:?}"),
        })
    };
    if !spin.is_zero() {
        let start = Instant::now();
        loop {
            if let Some(sample) = receive()? {
                return Ok(sample);
            }
            if start.elapsed() >= spin {
                break;
            }
            // Yield rather than spin: when the peer shares this core, a plain spin would keep
            // it from running at all until the time slice ends (tens of microseconds).
            std::thread::yield_now();
        }
    }
    let mut next_check = Instant::now() + tick;
    let _blocked = Blocked::raise(blocked);
    loop {
        if let Some(sample) = receive()? {
            return Ok(sample);
        }
        // At least 1 µs: the wait is a socket receive timeout, where zero (or anything that
        // rounds down to 0 µs) means "wait forever" — a hang if the peer died meanwhile.
        let timeout = next_check
            .saturating_duration_since(Instant::now())
            .max(Duration::from_micros(1));
        let interrupted = match listener.timed_wait(|_| {}, timeout) {
            Ok(_) => false,
            // A signal (Ctrl-C) cut the wait short: let the caller's check see it now.
            Err(ListenerWaitError::InterruptSignal) => true,
            Err(e) => {
                return Err(DataPlaneError::Ipc {
                    what: "wait",
                    detail: format!("{e:?}"),
                });
            }
        };
        if interrupted || Instant::now() >= next_check {
            alive()?;
            next_check = Instant::now() + tick;
        }
    }
}
