//! The one log set-up of every envhub process (the CLI, the workers, the Python module):
//! `tracing` events to stderr, filtered by `ENVHUB_LOG`, else `RUST_LOG`, else warnings.
//! Libraries only emit events; the processes call this once.

use crate::env_vars::ENVHUB_LOG;

/// Installs the subscriber (a second call, or one where another is installed, does nothing).
pub fn init_logging() {
    use tracing_subscriber::EnvFilter;
    let filter = std::env::var(ENVHUB_LOG)
        .ok()
        .or_else(|| std::env::var("RUST_LOG").ok())
        .unwrap_or_else(|| "warn".to_string());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(EnvFilter::new(filter))
        .with_writer(std::io::stderr)
        .try_init();
}
