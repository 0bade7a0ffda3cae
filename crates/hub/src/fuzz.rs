//! Fuzz targets for every parser of bytes that another process sends: a remote session's
//! request and response frames, rendered frames, an open reply with its spaces, a hub's or
//! daemon's error, a worker's failure report, a daemon request, a registry file, a Python
//! worker's info-column schema.
//!
//! Each target runs as a normal test: first its corpus (`fuzz/corpus/<target>/`, the one corpus
//! both tiers read: the seeds and every input that once found a bug, in the format the
//! cargo-fuzz target of the same name reads), then inputs that proptest makes by mutating
//! corpus entries (bit flips, boundary words, insertions, cuts, splices) or from raw bytes,
//! until `ENVHUB_FUZZ_SECS` seconds (default 2) have passed. A target fails on a panic or on a
//! broken invariant, and proptest shrinks the input it prints. Every run prints its count of
//! executions. `ENVHUB_FUZZ_SEED` picks the random stream (default: fixed, reproducible).
//!
//! This is the quick tier, run by every `cargo test`. The coverage-guided tier is the
//! cargo-fuzz crate `fuzz/` (libFuzzer with AddressSanitizer, `scripts/fuzz.sh`), with a target
//! for each of these parsers and more (docs/design/fuzzing.md).

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// One change to an input.
#[derive(Clone, Debug)]
enum Mutation {
    Flip(usize, u8),
    Set(usize, u8),
    Insert(usize, Vec<u8>),
    Remove(usize, usize),
    /// A little-endian `u32` at a 4-byte boundary: where headers keep their lengths.
    Word(usize, u32),
    Truncate(usize),
    /// Bytes of another corpus entry appended.
    Splice(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let word = prop_oneof![
        Just(0u32),
        Just(1),
        Just(2),
        Just(3),
        Just(16),
        Just(0x7fff_ffff),
        Just(0x8000_0000),
        Just(u32::MAX),
        any::<u32>(),
    ];
    prop_oneof![
        (any::<usize>(), 0u8..8).prop_map(|(at, bit)| Mutation::Flip(at, bit)),
        (any::<usize>(), any::<u8>()).prop_map(|(at, b)| Mutation::Set(at, b)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(at, b)| Mutation::Insert(at, b)),
        (any::<usize>(), 1usize..64).prop_map(|(at, n)| Mutation::Remove(at, n)),
        (any::<usize>(), word).prop_map(|(at, w)| Mutation::Word(at, w)),
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), any::<usize>()).prop_map(|(from, at)| Mutation::Splice(from, at)),
    ]
}

fn apply(seed: &[u8], corpus: &[Vec<u8>], mutations: &[Mutation]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for m in mutations {
        let len = b.len();
        match m {
            Mutation::Flip(at, bit) if len > 0 => b[at % len] ^= 1 << bit,
            Mutation::Set(at, v) if len > 0 => b[at % len] = *v,
            Mutation::Insert(at, v) => {
                let at = at % (len + 1);
                b.splice(at..at, v.iter().copied());
            }
            Mutation::Remove(at, n) if len > 0 => {
                let at = at % len;
                b.drain(at..(at + n).min(len));
            }
            Mutation::Word(at, w) if len >= 4 => {
                let at = (at % (len / 4)) * 4;
                b[at..at + 4].copy_from_slice(&w.to_le_bytes());
            }
            Mutation::Truncate(at) => b.truncate(at % (len + 1)),
            Mutation::Splice(from, at) if !corpus.is_empty() => {
                let other = &corpus[from % corpus.len()];
                let start = at % (other.len() + 1);
                b.extend_from_slice(&other[start..]);
            }
            _ => {}
        }
    }
    b
}

/// `fuzz/corpus/<target>/` of the repository: the cargo-fuzz targets' corpus.
fn corpus_dir(target: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target)
}

fn budget() -> Duration {
    let secs = std::env::var("ENVHUB_FUZZ_SECS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .unwrap_or(2.0);
    Duration::from_secs_f64(secs.max(0.0))
}

/// Runs `check` on the corpus of `target` (with `seeds` added), then on mutations of it
/// until the time budget is spent. `check` returns `Err` for a broken invariant; a parser's
/// error for bad input is `Ok`. Returns the executions.
fn fuzz(target: &str, seeds: Vec<Vec<u8>>, check: impl Fn(&[u8]) -> Result<(), String>) -> usize {
    let dir = corpus_dir(target);
    let mut corpus = seeds;
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("corpus {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    files.sort();
    for f in &files {
        corpus.push(std::fs::read(f).expect("corpus file"));
    }
    assert!(
        !corpus.is_empty(),
        "{target}: empty corpus in {}",
        dir.display()
    );
    let runs = AtomicUsize::new(0);
    let run = |bytes: &[u8]| {
        runs.fetch_add(1, Ordering::Relaxed);
        check(bytes)
    };
    for (k, input) in corpus.iter().enumerate() {
        if let Err(e) = run(input) {
            panic!("{target}: corpus input {k} breaks an invariant: {e}");
        }
    }
    let seed: u64 = std::env::var("ENVHUB_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(22);
    let n = corpus.len();
    let inputs = prop_oneof![
        9 => (0..n, prop::collection::vec(mutation(), 1..8))
            .prop_map({
                let corpus = corpus.clone();
                move |(i, m)| apply(&corpus[i], &corpus, &m)
            }),
        1 => prop::collection::vec(any::<u8>(), 0..512),
    ];
    let start = Instant::now();
    let budget = budget();
    let mut round = 0u64;
    while start.elapsed() < budget {
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&seed.to_le_bytes());
        key[8..16].copy_from_slice(&round.to_le_bytes());
        let config = Config {
            cases: 256,
            failure_persistence: None,
            ..Config::default()
        };
        let mut runner =
            TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &key));
        let result = runner.run(&inputs, |bytes| run(&bytes).map_err(TestCaseError::fail));
        if let Err(e) = result {
            panic!("{target}: {e} (ENVHUB_FUZZ_SEED={seed}, round {round})");
        }
        round += 1;
    }
    let executions = runs.load(Ordering::Relaxed);
    eprintln!(
        "fuzz {target}: {executions} executions in {:.1} s ({} corpus inputs), no finding",
        start.elapsed().as_secs_f64(),
        corpus.len()
    );
    executions
}

mod targets {
    use super::fuzz;
    use envhub_protocol::batch_codec::{self, RemoteAnswer, RequestBody, RowsOut};
    use envhub_protocol::untrusted::{check_open_reply, from_hub, read_failure_report};
    use envhub_protocol::{Frame, HubError, OpenReply};
    use envhub_shm::{BatchLayout, Layout, command};

    /// Layouts a frame is read against, picked by the input's first byte: the table of the
    /// cargo-fuzz crate's `layouts` (`fuzz/src/lib.rs`), so that a corpus input means the
    /// same message to both tiers.
    fn layouts(pick: u8) -> (Layout, BatchLayout) {
        let (n, act, obs, fin) = match pick % 5 {
            0 => (3, 4, 16, false),
            1 => (1, 8, 4, true),
            2 => (8, 1, 1, false),
            3 => (2, 0, 0, true),
            _ => (0, 0, 0, true),
        };
        (Layout::new(n, act), BatchLayout::new(n, obs, fin))
    }

    fn with_pick(pick: u8, bytes: Vec<u8>) -> Vec<u8> {
        let mut out = vec![pick];
        out.extend(bytes);
        out
    }

    #[test]
    fn fuzz_wire_request() {
        let mut seeds = Vec::new();
        for pick in 0..5u8 {
            let (layout, _) = layouts(pick);
            let n = layout.num_envs;
            let actions = vec![7u8; n * layout.act_bytes];
            let selected: Vec<bool> = (0..n).map(|i| i % 2 == 0).collect();
            let seeds_of: Vec<Option<u64>> = (0..n).map(|i| Some(i as u64)).collect();
            let body = RequestBody {
                actions: Some(&actions),
                selected: Some(&selected),
                seeds: &seeds_of,
                options: b"{\"x\": 1}",
            };
            seeds.push(with_pick(
                pick,
                batch_codec::encode_request(&layout, 1, command::RESET, 0, &body),
            ));
            seeds.push(with_pick(
                pick,
                batch_codec::encode_request(&layout, 2, command::STEP, 1, &RequestBody::NONE),
            ));
        }
        fuzz("wire_request", seeds, |bytes| {
            let Some((&pick, msg)) = bytes.split_first() else {
                return Ok(());
            };
            let (layout, _) = layouts(pick);
            if let Ok(r) = batch_codec::parse_request(msg, &layout) {
                let n = layout.num_envs;
                if r.actions.len() != n * layout.act_bytes
                    || r.seeds.len() != n
                    || r.selected.len() != n
                {
                    return Err(format!("parsed blocks of the wrong length for {n} envs"));
                }
            }
            Ok(())
        });
    }

    #[test]
    fn fuzz_wire_response() {
        let mut seeds = Vec::new();
        for pick in 0..5u8 {
            let (_, rows) = layouts(pick);
            let n = rows.num_envs;
            let mut block = vec![0u8; rows.size()];
            let obs = vec![1u8; n * rows.obs_bytes];
            let rewards = vec![0.5; n];
            let flags = vec![false; n];
            let envs: Vec<usize> = (0..n).collect();
            batch_codec::write_rows(
                &rows,
                &mut block,
                &envs,
                &RowsOut {
                    obs: &obs,
                    rewards: &rewards,
                    terminated: &flags,
                    truncated: &flags,
                    final_mask: &[],
                    final_obs: &[],
                },
            );
            seeds.push(with_pick(
                pick,
                batch_codec::encode_response(3, 0, n, &block, b"[{\"a\": 1}]"),
            ));
            let frames = envhub_shm::frames_section((0..n).map(|_| Some((2, 1, vec![9u8; 6]))));
            seeds.push(with_pick(
                pick,
                batch_codec::encode_response(4, 0, n, &[], &frames),
            ));
        }
        fuzz("wire_response", seeds, |bytes| {
            let Some((&pick, msg)) = bytes.split_first() else {
                return Ok(());
            };
            let (_, layout) = layouts(pick);
            let Some(answer) = RemoteAnswer::parse(msg.to_vec()) else {
                return Ok(());
            };
            if 24 + answer.rows().len() + answer.info_bytes().len() != msg.len() {
                return Err("the parts of an answer do not add up to its length".into());
            }
            // What the client does with it: land the rows when they have the slice's size,
            // read frames from the info section.
            let n = layout.num_envs;
            if answer.rows().len() == layout.size() {
                let mut slot = vec![0u64; layout.size().div_ceil(8)];
                let base: &mut [u8] = bytemuck::cast_slice_mut(&mut slot);
                // SAFETY: `base` holds `size()` bytes, 8-byte aligned, used only here.
                let mut to = unsafe { layout.rows_mut(base.as_mut_ptr(), 0, n) };
                let envs: Vec<usize> = (0..n).collect();
                batch_codec::land_rows(&layout, answer.rows(), &envs, &mut to, 0);
            }
            let mut rest = answer.info_bytes();
            for _ in 0..n {
                match Frame::parse(rest) {
                    Some((_, tail)) => rest = tail,
                    None => break,
                }
            }
            Ok(())
        });
    }

    #[test]
    fn fuzz_frames() {
        let seeds = vec![
            envhub_shm::frames_section([Some((2, 2, vec![1u8; 12])), None]),
            envhub_shm::frames_section([None]),
        ];
        fuzz("frames", seeds, |mut bytes| {
            while let Some((frame, rest)) = Frame::parse(bytes) {
                if let Some(f) = frame
                    && f.height.checked_mul(f.width).and_then(|p| p.checked_mul(3))
                        != Some(f.rgb.len())
                {
                    return Err(format!(
                        "a {}x{} frame of {} bytes",
                        f.height,
                        f.width,
                        f.rgb.len()
                    ));
                }
                if rest.len() >= bytes.len() {
                    return Err("a frame that takes no bytes".into());
                }
                bytes = rest;
            }
            Ok(())
        });
    }

    #[test]
    fn fuzz_open_reply() {
        fuzz("open_reply", Vec::new(), |bytes| {
            let Some((&pick, msg)) = bytes.split_first() else {
                return Ok(());
            };
            let Ok(reply) = serde_json::from_slice::<OpenReply>(msg) else {
                return Ok(());
            };
            let n = [1, 4, 1 << 20, usize::MAX / 4][usize::from(pick % 4)];
            if let Ok((req, rows)) = check_open_reply("fuzz", &reply, n, pick & 4 != 0) {
                let obs = reply.spec.observation_space.byte_len();
                if rows.obs_bytes != obs || req.act_bytes != reply.spec.action_space.byte_len() {
                    return Err("checked sizes differ from the spaces' own".into());
                }
                // The checked space may be used: leaves and validation of a zero value.
                let _ = reply.spec.observation_space.leaves();
                if obs <= 1 << 16 {
                    let _ = reply.spec.observation_space.validate(&vec![0u8; obs]);
                }
            }
            Ok(())
        });
    }

    /// Sealed session messages: whatever arrives on a session's keys is opened (or refused)
    /// without a panic, and nothing the fuzzer writes passes for the key's.
    #[test]
    fn fuzz_sealed() {
        use envhub_protocol::seal::{Cipher, Direction, SessionKey};
        let keys = Cipher::ALL.map(|c| SessionKey::new(c, &[5; 32]));
        let seeds: Vec<Vec<u8>> = keys
            .iter()
            .map(|key| {
                let mut sealed = 7u64.to_le_bytes().to_vec();
                sealed.extend_from_slice(&[0u8; 48]);
                key.seal(Direction::Request, &mut sealed);
                sealed
            })
            .collect();
        fuzz("sealed", seeds.clone(), |bytes| {
            for (key, sealed) in keys.iter().zip(&seeds) {
                for direction in [Direction::Request, Direction::Response] {
                    let mut m = bytes.to_vec();
                    if key.open(direction, &mut m).is_ok()
                        && !(direction == Direction::Request && bytes == &sealed[..])
                    {
                        return Err("bytes the fuzzer made opened with the session's key".into());
                    }
                }
            }
            Ok(())
        });
    }

    #[test]
    fn fuzz_hub_error() {
        fuzz("hub_error", Vec::new(), |bytes| {
            if let Ok(e) = serde_json::from_slice::<HubError>(bytes) {
                let _ = e.to_string();
                let taken = from_hub("fuzz", e);
                if matches!(
                    taken,
                    HubError::Interrupted | HubError::HubLost { .. } | HubError::Daemon { .. }
                ) {
                    return Err(format!("a hub's error passed as {taken:?}"));
                }
                let _ = taken.to_string();
            }
            Ok(())
        });
    }

    #[test]
    fn fuzz_failure_report() {
        fuzz("failure_report", Vec::new(), |bytes| {
            // As the cargo-fuzz target reads its input: the first byte's high nibble is the
            // worker's first env, its low one which of the worker's 4 envs were sent.
            let Some((&pick, msg)) = bytes.split_first() else {
                return Ok(());
            };
            let offset = usize::from(pick >> 4);
            let sent: Vec<usize> = (0..4)
                .filter(|i| pick & (1 << i) != 0)
                .map(|i| offset + i)
                .collect();
            if let Ok(report) = read_failure_report(msg, "worker 0", &sent, offset)
                && let Some((k, _)) = report
                    .failed
                    .iter()
                    .find(|(k, _)| !sent.contains(&(offset + k)))
            {
                return Err(format!("env {k} passed, which was not sent"));
            }
            Ok(())
        });
    }

    #[test]
    fn fuzz_daemon_request() {
        fuzz("daemon_request", Vec::new(), |bytes| {
            let text = String::from_utf8_lossy(bytes);
            if let Ok(request) = envhub_protocol::daemon::Request::parse(&text) {
                // What the client sends reads back as the same request.
                let again = envhub_protocol::daemon::Request::parse(&request.encode())
                    .map_err(|e| format!("an encoded {} request fails: {e}", request.op()))?;
                if again.op() != request.op() {
                    return Err("a request changed its op on the way".into());
                }
            }
            let _ = envhub_protocol::daemon::parse_reply(&text);
            Ok(())
        });
    }

    #[test]
    fn fuzz_registry_yaml() {
        let builtin = include_str!("../../../configs/env_registry.yaml");
        let seeds = vec![builtin.as_bytes()[..builtin.len().min(4000)].to_vec()];
        fuzz("registry_yaml", seeds, |bytes| {
            let text = String::from_utf8_lossy(bytes);
            let mut registry = envhub_catalog::Registry::from_entries(Vec::new(), "fuzz");
            let _ = registry.add_yaml(&text, "fuzz.yaml", std::path::Path::new("/nonexistent"));
            Ok(())
        });
    }

    #[test]
    fn fuzz_info_schema() {
        use envhub_protocol::info_columns::InfoSchema;
        let seeds = vec![
            br#"{"id": 9, "keys": [{"key": "x", "dtype": "<f8", "shape": [], "offset": 8, "mask": 40, "kind": "py"}, {"key": "v", "dtype": "<f4", "shape": [2, 3], "offset": 16, "mask": 41, "kind": "array"}]}"#.to_vec(),
            br#"{"id": 1, "keys": [{"key": "ok", "dtype": "|b1", "shape": [], "offset": 8, "mask": 9, "kind": "np"}]}"#.to_vec(),
        ];
        fuzz("info_schema", seeds, |bytes| {
            let text = String::from_utf8_lossy(bytes);
            for row in [0usize, 16, 48, 512] {
                let Ok(schema) = InfoSchema::parse(&text, row) else {
                    continue;
                };
                // What a reader relies on to lay views over a row: everything inside it,
                // aligned, and the id's bytes left alone.
                for c in &schema.columns {
                    let item: usize = c.dtype[2..].parse().unwrap_or(1);
                    let whole = c.shape.iter().try_fold(item, |a, &d| a.checked_mul(d));
                    if whole != Some(c.nbytes)
                        || c.offset + c.nbytes > row
                        || c.mask >= row
                        || c.mask < 8
                        || (c.nbytes > 0 && c.offset < 8)
                        || c.offset % item != 0
                    {
                        return Err(format!(
                            "schema passed with a bad column {c:?} in a row of {row}"
                        ));
                    }
                }
            }
            Ok(())
        });
    }
}
