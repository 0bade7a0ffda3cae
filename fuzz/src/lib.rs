//! What envhub's fuzz targets share: the layouts a message is read against, JSON round trips,
//! and structured inputs drawn from the fuzzer's bytes.

use arbitrary::Unstructured;
use envhub_shm::{BatchLayout, Layout};
use serde::{Serialize, de::DeserializeOwned};

/// Most envs and bytes per value a structured input draws: enough for every branch, small
/// enough that no input allocates much.
pub const MAX_ENVS: usize = 8;
/// See [`MAX_ENVS`].
pub const MAX_VALUE: usize = 32;

/// The request and result layouts a message is read against, picked by one byte: the shapes
/// a session has (several envs, one, none; with and without final observations).
pub fn layouts(pick: u8) -> (Layout, BatchLayout) {
    let (n, act, obs, fin) = match pick % 5 {
        0 => (3, 4, 16, false),
        1 => (1, 8, 4, true),
        2 => (8, 1, 1, false),
        3 => (2, 0, 0, true),
        _ => (0, 0, 0, true),
    };
    (Layout::new(n, act), BatchLayout::new(n, obs, fin))
}

/// Asserts that `value` (read from the fuzzer's bytes) survives its own encoding: what one
/// side writes, the other reads back as the same value.
pub fn assert_json_round_trip<T: Serialize + DeserializeOwned>(value: &T) {
    let text = serde_json::to_string(value).expect("a parsed value serializes");
    let back: T = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("its own encoding does not parse: {e}\n{text}"));
    let (a, b) = (
        serde_json::to_value(value).expect("serializes"),
        serde_json::to_value(&back).expect("serializes"),
    );
    assert_eq!(a, b, "decode(encode(x)) != x");
}

/// `n` bytes drawn from `u` (zeros once it runs dry).
pub fn bytes(u: &mut Unstructured<'_>, n: usize) -> Vec<u8> {
    let mut out = vec![0u8; n];
    let _ = u.fill_buffer(&mut out);
    out
}

/// A length below `max` drawn from `u`.
pub fn below(u: &mut Unstructured<'_>, max: usize) -> usize {
    u.int_in_range(0..=max.saturating_sub(1)).unwrap_or(0)
}
