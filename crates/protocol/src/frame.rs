//! Rendered frames as a worker encodes them in a response's info section.

/// An RGB frame, row-major, 3 bytes per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// `height × width × 3` bytes.
    pub rgb: Vec<u8>,
}

impl Frame {
    /// Reads one frame as the worker encodes it (`u32` height, `u32` width, pixels);
    /// `Some(None)` for an env that rendered nothing; `None` for bytes that do not hold what
    /// their sizes say (sizes are checked, never trusted: they come from another process).
    pub fn parse(bytes: &[u8]) -> Option<(Option<Frame>, &[u8])> {
        let h = u32::from_le_bytes(bytes.get(..4)?.try_into().ok()?) as usize;
        let w = u32::from_le_bytes(bytes.get(4..8)?.try_into().ok()?) as usize;
        let n = h.checked_mul(w)?.checked_mul(3)?;
        let rgb = bytes.get(8..8usize.checked_add(n)?)?;
        let frame = (n > 0).then(|| Frame {
            height: h,
            width: w,
            rgb: rgb.to_vec(),
        });
        Some((frame, &bytes[8 + n..]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encoded(h: u32, w: u32, pixels: &[u8]) -> Vec<u8> {
        let mut out = h.to_le_bytes().to_vec();
        out.extend_from_slice(&w.to_le_bytes());
        out.extend_from_slice(pixels);
        out
    }

    #[test]
    fn parses_a_frame_and_an_empty_one() {
        let mut bytes = encoded(1, 2, &[1, 2, 3, 4, 5, 6]);
        bytes.extend(encoded(0, 0, &[]));
        let (frame, rest) = Frame::parse(&bytes).unwrap();
        assert_eq!(frame.unwrap().rgb, [1, 2, 3, 4, 5, 6]);
        let (none, rest) = Frame::parse(rest).unwrap();
        assert!(none.is_none() && rest.is_empty());
    }

    #[test]
    fn sizes_beyond_the_bytes_or_overflowing_are_refused() {
        assert!(Frame::parse(&encoded(2, 2, &[0; 5])).is_none());
        assert!(Frame::parse(&encoded(u32::MAX, u32::MAX, &[0; 8])).is_none());
        assert!(Frame::parse(&[1, 0, 0]).is_none());
    }
}
