//! Writing float64 observations into the core's flat byte layout, and reading float32 actions.

/// Appends float64 values to an observation slot, little-endian; or only counts them (to size
/// the observation space from the same code that writes it).
pub(crate) struct ObsWriter<'a> {
    buf: Option<&'a mut [u8]>,
    len: usize,
}

impl<'a> ObsWriter<'a> {
    /// Writes into `buf`, which must hold exactly the observation.
    pub(crate) fn new(buf: &'a mut [u8]) -> Self {
        ObsWriter {
            buf: Some(buf),
            len: 0,
        }
    }

    /// Counts values without writing them.
    pub(crate) fn counting() -> ObsWriter<'static> {
        ObsWriter { buf: None, len: 0 }
    }

    /// Values written (or counted) so far.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    pub(crate) fn push(&mut self, v: f64) {
        if let Some(buf) = self.buf.as_deref_mut() {
            buf[self.len * 8..self.len * 8 + 8].copy_from_slice(&v.to_le_bytes());
        }
        self.len += 1;
    }

    pub(crate) fn extend(&mut self, values: impl IntoIterator<Item = f64>) {
        for v in values {
            self.push(v);
        }
    }

    /// Checks that the whole slot was written.
    pub(crate) fn finish(self) {
        if let Some(buf) = self.buf {
            assert_eq!(buf.len(), self.len * 8, "observation length mismatch");
        }
    }
}

/// A `Box(float32)` action as `f32`s, into `out`.
pub(crate) fn read_f32s(action: &[u8], out: &mut Vec<f32>) {
    out.clear();
    out.extend(
        action
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes"))),
    );
}
