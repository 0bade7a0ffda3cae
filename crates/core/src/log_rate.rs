//! A bound on how many lines one log statement writes a second.
//!
//! A peer can make a statement log once per thing it sends: Zenoh warns once per failed TLS
//! handshake, so a port flood of garbage handshakes wrote hundreds of lines a second to a
//! hub's log, for as long as the flood lasted. Each statement (callsite) at `INFO` or above
//! writes at most [`LINES_PER_SECOND`] lines a second. As it starts dropping lines one line
//! says so at once; their count is said in one line when the statement next writes. `DEBUG` and `TRACE` are never dropped:
//! whoever asked for them asked for every line.

use std::collections::HashMap;
use std::io::Write;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tracing::callsite::Identifier;
use tracing::subscriber::Interest;
use tracing::{Level, Metadata};
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::time::{FormatTime, SystemTime};
use tracing_subscriber::layer::{Context, Filter};

/// Lines one statement writes a second at most.
pub const LINES_PER_SECOND: u32 = 20;

const WINDOW: Duration = Duration::from_secs(1);

/// One statement's count in its current window.
struct Window {
    start: Instant,
    written: u32,
    dropped: u64,
    /// Whether the window before dropped lines too (a flood goes on: its start was said).
    flooding: bool,
}

/// The per-layer filter (see the module's documentation). `note` receives the line that says
/// how many lines a statement dropped.
pub struct RateLimit<W> {
    windows: Mutex<HashMap<Identifier, Window>>,
    note: Mutex<W>,
}

impl<W: Write> RateLimit<W> {
    /// Says dropped lines to `note` (stderr, where the log goes).
    pub fn new(note: W) -> Self {
        RateLimit {
            windows: Mutex::new(HashMap::new()),
            note: Mutex::new(note),
        }
    }

    /// One line about `meta`'s statement, in the log's own format (time, level, target).
    fn say(&self, meta: &Metadata<'_>, what: std::fmt::Arguments<'_>) {
        let mut time = String::new();
        let _ = SystemTime.format_time(&mut Writer::new(&mut time));
        if let Ok(mut note) = self.note.lock() {
            let _ = writeln!(
                note,
                "{time} {:>5} {}: {what} ({}:{}; at most {LINES_PER_SECOND} lines a second)",
                meta.level(),
                meta.target(),
                meta.file().unwrap_or("?"),
                meta.line().unwrap_or(0),
            );
        }
    }

    /// Whether this event of `meta`'s statement may be written now.
    fn admit(&self, meta: &Metadata<'_>, now: Instant) -> bool {
        let Ok(mut windows) = self.windows.lock() else {
            return true; // a panic while counting: write rather than lose lines
        };
        let window = windows.entry(meta.callsite()).or_insert(Window {
            start: now,
            written: 0,
            dropped: 0,
            flooding: false,
        });
        if now.duration_since(window.start) >= WINDOW {
            if window.dropped > 0 {
                let dropped = window.dropped;
                self.say(
                    meta,
                    format_args!("{dropped} more lines of this statement were not written"),
                );
            }
            *window = Window {
                start: now,
                written: 0,
                dropped: 0,
                flooding: window.dropped > 0,
            };
        }
        if window.written < LINES_PER_SECOND {
            window.written += 1;
            return true;
        }
        if window.dropped == 0 && !window.flooding {
            // Said at once, so that a reader knows of dropped lines even if the statement
            // never writes again to give their count.
            self.say(
                meta,
                format_args!(
                    "this statement drops lines from now on; their count is said when it next writes"
                ),
            );
        }
        window.dropped += 1;
        false
    }
}

/// Spans are not lines, and `DEBUG` and `TRACE` are wanted whole.
fn limited(meta: &Metadata<'_>) -> bool {
    meta.is_event() && *meta.level() <= Level::INFO
}

impl<S, W: Write> Filter<S> for RateLimit<W> {
    fn enabled(&self, meta: &Metadata<'_>, _: &Context<'_, S>) -> bool {
        !limited(meta) || self.admit(meta, Instant::now())
    }

    fn callsite_enabled(&self, meta: &'static Metadata<'static>) -> Interest {
        // Asked for each event of a limited statement; nothing counted here.
        if limited(meta) {
            Interest::sometimes()
        } else {
            Interest::always()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use tracing_subscriber::filter::FilterExt;
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::{EnvFilter, Layer};

    /// A shared buffer, as stderr stands for in the processes.
    #[derive(Clone, Default)]
    struct Buffer(Arc<Mutex<Vec<u8>>>);

    impl Write for Buffer {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(bytes);
            Ok(bytes.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Buffer {
        fn lines(&self) -> Vec<String> {
            let text = String::from_utf8(self.0.lock().unwrap().clone()).unwrap();
            text.lines().map(str::to_string).collect()
        }
    }

    /// Logs `n` warnings from one statement (and `n` info lines the level filter drops first,
    /// and 5 debug lines) under the filter, then one more warning a window later; returns the
    /// lines written and the windows the run spanned.
    fn flood(n: u64) -> (Vec<String>, u64) {
        let out = Buffer::default();
        let writer = out.clone();
        let layer = tracing_subscriber::fmt::layer()
            .with_ansi(false)
            .with_writer(move || writer.clone())
            .with_filter(EnvFilter::new("warn,envhub_core=debug").and(RateLimit::new(out.clone())));
        let subscriber = tracing_subscriber::registry().with(layer);
        fn handshake_failed(i: u64) {
            tracing::warn!(i, "failed handshake");
        }
        let start = Instant::now();
        tracing::subscriber::with_default(subscriber, || {
            for i in 0..n {
                handshake_failed(i);
                tracing::info!(target: "elsewhere", i, "unwanted info"); // filtered out first: never counted
            }
            for i in 0..5 {
                tracing::debug!(i, "wanted debug");
            }
            // The next window: the count of what was dropped is said, then this line.
            std::thread::sleep(WINDOW);
            handshake_failed(n);
        });
        let windows = start.elapsed().as_secs() + 1;
        (out.lines(), windows)
    }

    #[test]
    fn a_flooding_statement_writes_at_most_its_share_a_second_and_says_what_it_dropped() {
        let n = 5_000;
        let (lines, windows) = flood(n);
        let warnings: Vec<_> = lines
            .iter()
            .filter(|l| l.contains("failed handshake"))
            .collect();
        let notes: Vec<_> = lines.iter().filter(|l| l.contains("more lines")).collect();
        // The flood's start is said once, however many windows it spans.
        let starts = lines
            .iter()
            .filter(|l| l.contains("drops lines from now on"))
            .count();
        assert_eq!(starts, 1, "{lines:?}");
        assert!(
            warnings.len() as u64 <= windows * u64::from(LINES_PER_SECOND),
            "{} lines in {windows} windows",
            warnings.len()
        );
        assert!(warnings.len() >= LINES_PER_SECOND as usize, "{lines:?}");
        // Every warning is written or counted as dropped, none lost unsaid.
        let dropped: u64 = notes
            .iter()
            .map(|l| {
                let after = l.split(": ").nth(1).unwrap(); // after the target
                after.split(' ').next().unwrap().parse::<u64>().unwrap()
            })
            .sum();
        assert_eq!(warnings.len() as u64 + dropped, n + 1, "{notes:?}");
        assert!(notes[0].contains("log_rate.rs"), "{notes:?}");
        assert_eq!(
            lines.iter().filter(|l| l.contains("wanted debug")).count(),
            5
        );
        assert!(
            !lines.iter().any(|l| l.contains("unwanted info")),
            "{lines:?}"
        );
    }

    #[test]
    fn a_quiet_statement_loses_nothing() {
        let (lines, _) = flood(LINES_PER_SECOND as u64 - 1);
        assert_eq!(
            lines
                .iter()
                .filter(|l| l.contains("failed handshake"))
                .count(),
            LINES_PER_SECOND as usize
        );
        assert!(
            !lines
                .iter()
                .any(|l| l.contains("more lines") || l.contains("drops lines from now on")),
            "{lines:?}"
        );
    }
}
