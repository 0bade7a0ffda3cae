//! The one thread that spawns worker processes (and fork servers), so that the kernel's
//! parent-death signal is tied to a thread that lives as long as the process.

use std::process::{Child, Command};
use std::sync::{Mutex, mpsc};

/// Spawns `command` on the spawner thread, one thread that lives as long as the process.
///
/// Workers die with their parent through the kernel's parent-death signal (see
/// [`envhub_shm::die_with_parent`]), which fires when the *thread* that forked the child
/// ends; sessions start their workers from short-lived threads (one per worker, and Python
/// users make envs in threads that end), so no worker is forked from those.
pub(crate) fn spawn(command: Command) -> std::io::Result<Child> {
    type Request = (Command, mpsc::Sender<std::io::Result<Child>>);
    /// The spawner's channel, with the pid of the process it belongs to: a forked child
    /// (Python's `multiprocessing`) inherits the channel but not the thread, and starts its own.
    static SPAWNER: Mutex<Option<(u32, mpsc::Sender<Request>)>> = Mutex::new(None);
    let gone = || std::io::Error::other("the thread that spawns workers is gone");
    let (tx, rx) = mpsc::channel();
    {
        let mut spawner = SPAWNER.lock().unwrap_or_else(|e| e.into_inner());
        let pid = std::process::id();
        if spawner.as_ref().is_none_or(|(owner, _)| *owner != pid) {
            let (requests, incoming) = mpsc::channel::<Request>();
            std::thread::Builder::new()
                .name("envhub-spawner".into())
                .spawn(move || {
                    for (mut command, reply) in incoming {
                        let _ = reply.send(command.spawn());
                    }
                })?;
            *spawner = Some((pid, requests));
        }
        let (_, requests) = spawner.as_ref().ok_or_else(gone)?;
        requests.send((command, tx)).map_err(|_| gone())?;
    }
    rx.recv().map_err(|_| gone())?
}
