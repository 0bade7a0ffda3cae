//! Reading actions from and writing observations into the core's flat byte layout.

/// Writes `values` as little-endian `float32`s; `obs` must be exactly their size.
pub(crate) fn write_f32s(obs: &mut [u8], values: &[f32]) {
    assert_eq!(
        obs.len(),
        values.len() * 4,
        "observation buffer has the wrong length"
    );
    for (bytes, v) in obs.chunks_exact_mut(4).zip(values) {
        bytes.copy_from_slice(&v.to_le_bytes());
    }
}

/// A `Discrete` action: one little-endian `int64`.
pub(crate) fn read_discrete(action: &[u8]) -> i64 {
    i64::from_le_bytes(
        action[..8]
            .try_into()
            .expect("a discrete action is 8 bytes"),
    )
}

/// The single element of a `Box((1,), float32)` action.
pub(crate) fn read_f32(action: &[u8]) -> f32 {
    f32::from_le_bytes(action[..4].try_into().expect("a box action is 4 bytes"))
}
