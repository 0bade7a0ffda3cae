//! A raw iceoryx2 round trip, for benchmarks: the floor under envhub's data plane, measured in
//! the same run. One side publishes a small sample and notifies; the other answers the same
//! way. Both wait as envhub's channels do (spin with yields, then block on the listener), so
//! the difference to an envhub round trip is what envhub adds: request layout, slot, serve
//! loop, batch code.

use crate::DataPlaneError;
use crate::transport::{Ipc, node};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::time::{Duration, Instant};

fn iox<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> DataPlaneError {
    move |e| DataPlaneError::Ipc {
        what,
        detail: format!("{e:?}"),
    }
}

struct End {
    publisher: Publisher<Ipc, [u8; 64], ()>,
    notifier: Notifier<Ipc>,
    subscriber: Subscriber<Ipc, [u8; 64], ()>,
    listener: Listener<Ipc>,
    _node: Node<Ipc>,
}

fn open(prefix: &str, service: &str, ping: bool) -> Result<End, DataPlaneError> {
    let node = node(prefix, &format!("pingpong-{}", std::process::id()))?;
    let name =
        |dir: &str| ServiceName::new(&format!("{service}/{dir}")).map_err(iox("service name"));
    let (out, inn) = if ping {
        ("ping", "pong")
    } else {
        ("pong", "ping")
    };
    let service_of = |dir: &str| -> Result<_, DataPlaneError> {
        node.service_builder(&name(dir)?)
            .publish_subscribe::<[u8; 64]>()
            .max_publishers(1)
            .max_subscribers(1)
            .open_or_create()
            .map_err(iox("publish-subscribe service"))
    };
    let events_of = |dir: &str| -> Result<_, DataPlaneError> {
        node.service_builder(&name(dir)?)
            .event()
            .open_or_create()
            .map_err(iox("event service"))
    };
    let (tx, rx) = (service_of(out)?, service_of(inn)?);
    let (tx_events, rx_events) = (events_of(out)?, events_of(inn)?);
    Ok(End {
        publisher: tx.publisher_builder().create().map_err(iox("publisher"))?,
        notifier: tx_events
            .notifier_builder()
            .create()
            .map_err(iox("notifier"))?,
        subscriber: rx
            .subscriber_builder()
            .create()
            .map_err(iox("subscriber"))?,
        listener: rx_events
            .listener_builder()
            .create()
            .map_err(iox("listener"))?,
        _node: node,
    })
}

impl End {
    fn send(&self, n: u64) -> Result<(), DataPlaneError> {
        let mut payload = [0u8; 64];
        payload[..8].copy_from_slice(&n.to_le_bytes());
        let sample = self.publisher.loan_uninit().map_err(iox("loan"))?;
        sample.write_payload(payload).send().map_err(iox("send"))?;
        self.notifier.notify().map_err(iox("notify"))?;
        Ok(())
    }

    /// The next sample's number, spinning up to `spin` before blocking; `None` after `give_up`.
    fn receive(&self, spin: Duration, give_up: Duration) -> Result<Option<u64>, DataPlaneError> {
        let start = Instant::now();
        loop {
            if let Some(s) = self.subscriber.receive().map_err(iox("receive"))? {
                return Ok(Some(u64::from_le_bytes(
                    s.payload()[..8].try_into().expect("8"),
                )));
            }
            let waited = start.elapsed();
            if waited >= give_up {
                return Ok(None);
            }
            if waited < spin {
                std::thread::yield_now();
            } else {
                let _ = self.listener.timed_wait(|_| {}, Duration::from_millis(5));
            }
        }
    }
}

/// Answers pings on `service` until none comes for `idle` (the other side of [`ping`]).
pub fn pong(
    prefix: &str,
    service: &str,
    spin: Duration,
    idle: Duration,
) -> Result<(), DataPlaneError> {
    let end = open(prefix, service, false)?;
    while let Some(n) = end.receive(spin, idle)? {
        end.send(n)?;
    }
    Ok(())
}

/// Times `n` round trips to a [`pong`] on `service` (after a warm-up), spinning up to `spin`
/// on each answer. Gives up when an answer takes longer than `give_up`.
pub fn ping(
    prefix: &str,
    service: &str,
    n: usize,
    spin: Duration,
    give_up: Duration,
) -> Result<Vec<Duration>, DataPlaneError> {
    let end = open(prefix, service, true)?;
    let mut times = Vec::with_capacity(n);
    // The pong side may still be starting: the first answer is waited for longer.
    let mut k = 0u64;
    let started = Instant::now();
    loop {
        end.send(k)?;
        if end.receive(spin, Duration::from_millis(50))?.is_some() {
            break;
        }
        if started.elapsed() > give_up {
            return Err(DataPlaneError::PeerGone(
                "the pong side did not answer".into(),
            ));
        }
        k += 1;
    }
    for i in 0..(n + 1000) {
        let t = Instant::now();
        end.send(i as u64)?;
        if end.receive(spin, give_up)?.is_none() {
            return Err(DataPlaneError::PeerGone(
                "the pong side stopped answering".into(),
            ));
        }
        if i >= 1000 {
            times.push(t.elapsed());
        }
    }
    Ok(times)
}
