//! A remote hub's response as the client reads it (`RemoteAnswer::parse`), then used as the
//! client uses it: result rows landed in a batch slot when they have the slice's size (for
//! the envs sent), the info section read as JSON infos, a failure report, a hub's error
//! (`decode_error`, `from_hub`) and rendered frames. The first byte picks the layout and
//! which envs were sent; a response the hub encodes reads back as sent.
#![no_main]

use arbitrary::Unstructured;
use envhub_fuzz::{below, bytes, layouts};
use envhub_protocol::batch_codec::{self, RESPONSE_HEADER, RemoteAnswer};
use envhub_protocol::untrusted::{from_hub, read_failure_report};
use envhub_protocol::{Frame, HubError};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, msg)) = data.split_first() else {
        return;
    };
    let (_, layout) = layouts(pick);
    if let Some(answer) = RemoteAnswer::parse(msg.to_vec()) {
        assert_eq!(
            RESPONSE_HEADER + answer.rows().len() + answer.info_bytes().len(),
            msg.len()
        );
        let n = layout.num_envs;
        // The envs sent: all, or every other one (rows picked one by one).
        let sent: Vec<usize> = (0..n).filter(|e| pick & 0x80 == 0 || e % 2 == 0).collect();
        if answer.rows().len() == layout.size() {
            let mut slot = vec![0u64; layout.size().div_ceil(8)];
            let base: &mut [u8] = bytemuck::cast_slice_mut(&mut slot);
            // SAFETY: `base` holds `size()` bytes, 8-byte aligned, used only here.
            let mut to = unsafe { layout.rows_mut(base.as_mut_ptr(), 0, n) };
            batch_codec::land_rows(&layout, answer.rows(), &sent, &mut to, 0);
        }
        let info = answer.info_bytes();
        let _ = serde_json::from_slice::<serde_json::Value>(info);
        let _ = read_failure_report(info, "hub `fuzz`", &sent, 0);
        match batch_codec::decode_error("fuzz", info) {
            HubError::WorkerDied { .. } => {}
            e => {
                let e = from_hub("fuzz", e);
                assert!(!matches!(
                    e,
                    HubError::Interrupted | HubError::HubLost { .. } | HubError::Daemon { .. }
                ));
                let _ = e.to_string();
            }
        }
        let mut rest = info;
        for _ in 0..n {
            match Frame::parse(rest) {
                Some((_, tail)) => rest = tail,
                None => break,
            }
        }
    }
    round_trip(&mut Unstructured::new(data));
});

/// A response drawn from the input, encoded as the hub does: it parses to what was sent.
fn round_trip(u: &mut Unstructured<'_>) {
    let (seq, status, num_envs): (u64, u32, u8) = (
        u.arbitrary().unwrap_or(0),
        u.arbitrary().unwrap_or(0),
        u.arbitrary().unwrap_or(0),
    );
    let (rows_len, info_len) = (below(u, 256), below(u, 256));
    let (rows, info) = (bytes(u, rows_len), bytes(u, info_len));
    let encoded = batch_codec::encode_response(seq, status, num_envs.into(), &rows, &info);
    let answer = RemoteAnswer::parse(encoded).expect("an encoded response parses");
    let h = answer.header();
    assert_eq!(
        (h.seq, h.status, h.num_envs),
        (seq, status, num_envs.into())
    );
    assert_eq!((answer.rows(), answer.info_bytes()), (&rows[..], &info[..]));
}
