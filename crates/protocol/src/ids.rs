//! Names of sessions: unique on this machine and over time, and safe in shared-memory file
//! names and Zenoh keys (digits, hex digits and dashes). They start with the creating
//! process's pid in decimal: the data plane's stale-slot cleanup reads it back.

use std::sync::atomic::{AtomicU64, Ordering};

/// A new session id: this process (decimal), a counter and the clock (hex):
/// `<pid>-<n>-<nanos>`.
pub fn session_id() -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    format!(
        "{}-{:x}-{:x}",
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
        let pid: u32 = a.split('-').next().unwrap().parse().unwrap();
        assert_eq!(
            pid,
            std::process::id(),
            "the stale-slot cleanup reads the pid back"
        );
    }
}
