//! The one log set-up of every envhub process (the CLI, the workers, the Python module):
//! `tracing` events to stderr, filtered by `ENVHUB_LOG`, else `RUST_LOG`, else warnings, and
//! each statement at most [`LINES_PER_SECOND`](crate::log_rate::LINES_PER_SECOND) lines a
//! second (`log_rate`). Libraries only emit events; the processes call this once.

use crate::env_vars::ENVHUB_LOG;
use crate::log_rate::RateLimit;
use std::io::IsTerminal;

/// Installs the subscriber (a second call, or one where another is installed, does nothing).
pub fn init_logging() {
    use tracing_subscriber::filter::FilterExt;
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    use tracing_subscriber::{EnvFilter, Layer};
    let filter = std::env::var(ENVHUB_LOG)
        .ok()
        .or_else(|| std::env::var("RUST_LOG").ok())
        .unwrap_or_else(|| "warn".to_string());
    // The level filter first, so lines it drops are not counted against a statement's rate.
    // Colour only for a terminal: a hub's log redirected to a file stays plain text.
    let layer = tracing_subscriber::fmt::layer()
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .with_filter(EnvFilter::new(filter).and(RateLimit::new(std::io::stderr())));
    let _ = tracing_subscriber::registry().with(layer).try_init();
}
