//! Starting workers: the engine asks, the layer above decides how (a child of this process,
//! or of a hub daemon; which interpreter; which binary).

use envhub_protocol::HubError;
use envhub_shm::{ReadySpec, WorkerJob};
use std::time::Duration;

/// A started worker process, whoever started it.
pub trait Process: Send {
    /// Its pid.
    fn pid(&self) -> u32;
    /// Kills it (SIGKILL) and reaps it.
    fn kill(&mut self);
    /// Sends SIGKILL without waiting for its status (a session being given up).
    fn kill_now(&mut self);
    /// How it ended, waiting up to `timeout` for it to end ("died (signal: 9 (SIGKILL))").
    fn exit_status(&mut self, timeout: Duration) -> Option<String>;
}

/// Starts the worker of a job and waits until it reports ready.
pub trait Launch: Send + Sync {
    /// Starts a worker for `job`; its ready report within `start_timeout`, else an error.
    fn launch(
        &self,
        job: &WorkerJob,
        start_timeout: Duration,
    ) -> Result<(Box<dyn Process>, ReadySpec), HubError>;
}
