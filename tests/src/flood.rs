//! A flood of silent TCP connections held on a hub's port, as anyone who reaches the port
//! can hold them: no byte sent, and each one the hub drops opened again.

use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Raises this process's limit of open files to hold `wanted` sockets (a flood's), or fails
/// naming the machine's hard limit.
pub fn hold_open_files(wanted: u64) {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit with a valid resource and a pointer to a local struct.
    unsafe {
        assert_eq!(libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit), 0);
        let hard = limit.rlim_max;
        // Root may raise the hard limit too (the hubs the test starts inherit it).
        limit.rlim_max = limit.rlim_max.max(wanted);
        limit.rlim_cur = limit.rlim_cur.max(wanted);
        assert_eq!(
            libc::setrlimit(libc::RLIMIT_NOFILE, &limit),
            0,
            "this machine's hard limit of open files ({hard}) is below the {wanted} the flood \
             needs, and this user cannot raise it (`ulimit -Hn {wanted}` as root)"
        );
    }
}

/// `n` silent connections to one address, held by a thread of their own until [`stop`].
///
/// [`stop`]: SilentFlood::stop
pub struct SilentFlood {
    held: usize,
    holding: Arc<AtomicBool>,
    opened: Arc<AtomicUsize>,
    dropped: Arc<AtomicUsize>,
    holder: JoinHandle<()>,
}

impl SilentFlood {
    /// Starts holding `n` connections to `address`: every 250 ms each slot is looked at, a
    /// connection the hub closed is counted as dropped, and an empty slot is connected again.
    pub fn hold(address: SocketAddr, n: usize) -> SilentFlood {
        let holding = Arc::new(AtomicBool::new(true));
        let (opened, dropped) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let holder = {
            let (holding, opened, dropped) = (holding.clone(), opened.clone(), dropped.clone());
            std::thread::spawn(move || {
                let mut held: Vec<Option<TcpStream>> = (0..n).map(|_| None).collect();
                while holding.load(Ordering::Relaxed) {
                    for slot in &mut held {
                        let closed = slot.as_mut().is_some_and(|s| {
                            let mut b = [0u8; 64];
                            match std::io::Read::read(s, &mut b) {
                                Ok(0) => true,
                                Err(e) => e.kind() != std::io::ErrorKind::WouldBlock,
                                Ok(_) => false,
                            }
                        });
                        if closed {
                            dropped.fetch_add(1, Ordering::Relaxed);
                            *slot = None;
                        }
                        if slot.is_none() {
                            *slot =
                                TcpStream::connect_timeout(&address, Duration::from_millis(200))
                                    .ok()
                                    .inspect(|s| {
                                        s.set_nonblocking(true).unwrap();
                                        opened.fetch_add(1, Ordering::Relaxed);
                                    });
                        }
                        if !holding.load(Ordering::Relaxed) {
                            break;
                        }
                    }
                    std::thread::sleep(Duration::from_millis(250));
                }
            })
        };
        SilentFlood {
            held: n,
            holding,
            opened,
            dropped,
            holder,
        }
    }

    /// Waits until every connection has been opened once, failing after `timeout`.
    pub fn wait_held(&self, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        while self.opened() < self.held {
            assert!(
                Instant::now() < deadline,
                "could not open {} connections to the hub in {timeout:?} ({} opened)",
                self.held,
                self.opened()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Connections opened so far, the reopened ones included.
    pub fn opened(&self) -> usize {
        self.opened.load(Ordering::Relaxed)
    }

    /// Connections the hub has closed so far.
    pub fn dropped(&self) -> usize {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Stops holding and closes every connection.
    pub fn stop(self) {
        self.holding.store(false, Ordering::Relaxed);
        self.holder.join().unwrap();
    }
}
