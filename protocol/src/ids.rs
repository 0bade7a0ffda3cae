//! Names of sessions: unique on this machine and over time, and safe in shared-memory file
//! names and Zenoh keys (hex digits and dashes).

use std::sync::atomic::{AtomicU64, Ordering};

/// A new session id: this process, a counter and the clock (`<pid>-<n>-<nanos>`, in hex).
pub fn session_id() -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    format!(
        "{:x}-{:x}-{:x}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed),
        nanos & 0xffff_ffff_ffff
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn ids_differ_and_are_plain() {
        let (a, b) = (super::session_id(), super::session_id());
        assert_ne!(a, b);
        assert!(a.chars().all(|c| c.is_ascii_hexdigit() || c == '-'), "{a}");
    }
}
