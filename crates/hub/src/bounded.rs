//! Waiting on child processes with a bound: a child that hangs (a blocking import in an
//! adapter module, a worker stuck on exit) is killed, and the caller says what hung, instead
//! of waiting forever.

use std::io::Read;
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Why [`output_within`] has no output.
#[derive(Debug)]
pub(crate) enum RunError {
    /// The command could not be started.
    Start(std::io::Error),
    /// It was still running at the bound, so it was killed.
    Hung(Duration),
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Start(e) => write!(f, "{e}"),
            RunError::Hung(bound) => write!(
                f,
                "it did not finish within {}, so it was killed",
                seconds(*bound)
            ),
        }
    }
}

/// Runs `command` to the end as [`Command::output`] does, but kills it if it has not finished
/// within `timeout`.
pub(crate) fn output_within(command: &mut Command, timeout: Duration) -> Result<Output, RunError> {
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(RunError::Start)?;
    // Read both pipes on their own threads, so a chatty child never blocks on a full pipe.
    let read = |pipe: Option<Box<dyn Read + Send>>| {
        let (tx, rx) = mpsc::channel();
        if let Some(mut pipe) = pipe {
            std::thread::spawn(move || {
                let mut bytes = Vec::new();
                let _ = pipe.read_to_end(&mut bytes);
                let _ = tx.send(bytes);
            });
        }
        rx
    };
    let stdout = read(child.stdout.take().map(|p| Box::new(p) as _));
    let stderr = read(child.stderr.take().map(|p| Box::new(p) as _));
    let deadline = Instant::now() + timeout;
    let Some(status) = wait_within(&mut child, timeout) else {
        return Err(RunError::Hung(timeout));
    };
    // A grandchild may still hold the pipes open: take what came until the deadline.
    let collect = |rx: mpsc::Receiver<Vec<u8>>| {
        let left = deadline.saturating_duration_since(Instant::now());
        rx.recv_timeout(left.max(Duration::from_millis(100)))
            .unwrap_or_default()
    };
    Ok(Output {
        status,
        stdout: collect(stdout),
        stderr: collect(stderr),
    })
}

/// Waits up to `timeout` for `child` to exit; if it has not, kills (SIGKILL) and reaps it
/// and returns `None`.
pub(crate) fn wait_within(child: &mut Child, timeout: Duration) -> Option<ExitStatus> {
    let deadline = Instant::now() + timeout;
    let mut pause = Duration::from_millis(1);
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Some(status),
            Ok(None) if Instant::now() < deadline => {
                std::thread::sleep(pause);
                pause = (pause * 2).min(Duration::from_millis(50));
            }
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
        }
    }
}

/// `2 s`, `0.5 s`: a duration as people write it.
pub(crate) fn seconds(d: Duration) -> String {
    format!("{} s", d.as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_that_hangs_is_killed_at_the_bound() {
        // The mechanism, not the clock: killed at the bound ends it long before the sleep
        // would, even on a machine many times slower.
        let start = Instant::now();
        let err =
            output_within(Command::new("sleep").arg("30"), Duration::from_millis(200)).unwrap_err();
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "{:?}",
            start.elapsed()
        );
        assert!(matches!(err, RunError::Hung(_)), "{err:?}");
        assert!(
            err.to_string().contains("did not finish within 0.2 s"),
            "{err}"
        );
    }

    #[test]
    fn a_command_that_finishes_gives_its_output() {
        let out = output_within(
            Command::new("sh").args(["-c", "echo out; echo err >&2; exit 3"]),
            Duration::from_secs(10),
        )
        .unwrap();
        assert_eq!(out.status.code(), Some(3));
        assert_eq!(out.stdout, b"out\n");
        assert_eq!(out.stderr, b"err\n");
    }
}
