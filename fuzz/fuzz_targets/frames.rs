//! Rendered frames in a response's info section (`Frame::parse`), read one after another as
//! the client does: sizes are checked, never trusted. Frames a worker encodes
//! (`frames_section`) read back as sent.
#![no_main]

use arbitrary::Unstructured;
use envhub_fuzz::{below, bytes};
use envhub_protocol::Frame;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut rest = data;
    while let Some((frame, tail)) = Frame::parse(rest) {
        if let Some(f) = &frame {
            assert_eq!(
                Some(f.rgb.len()),
                f.height.checked_mul(f.width).and_then(|p| p.checked_mul(3))
            );
        }
        assert!(tail.len() < rest.len(), "a frame that takes no bytes");
        rest = tail;
    }
    // Frames drawn from the input, as a worker writes them.
    let mut u = Unstructured::new(data);
    let frames: Vec<Option<(usize, usize, Vec<u8>)>> = (0..below(&mut u, 4))
        .map(|_| {
            let (h, w) = (below(&mut u, 9), below(&mut u, 9));
            (h * w > 0 && u.arbitrary().unwrap_or(true)).then(|| (h, w, bytes(&mut u, h * w * 3)))
        })
        .collect();
    let section = envhub_shm::frames_section(frames.clone());
    let mut rest = &section[..];
    for sent in frames {
        let (frame, tail) = Frame::parse(rest).expect("an encoded frame parses");
        assert_eq!(frame.map(|f| (f.height, f.width, f.rgb)), sent);
        rest = tail;
    }
    assert!(rest.is_empty());
});
