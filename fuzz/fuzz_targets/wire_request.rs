//! A remote session's request as a hub reads it (`batch_codec::parse_request`): header, request
//! blocks of the session's layout, reset options. Bytes are read against one of several
//! layouts (the first byte picks it); a request the client encodes reads back as sent.
#![no_main]

use arbitrary::Unstructured;
use envhub_fuzz::{MAX_ENVS, MAX_VALUE, below, bytes, layouts};
use envhub_protocol::batch_codec::{self, RequestBody};
use envhub_shm::{Layout, command};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, msg)) = data.split_first() else {
        return;
    };
    let (layout, _) = layouts(pick);
    if let Ok(r) = batch_codec::parse_request(msg, &layout) {
        let n = layout.num_envs;
        assert_eq!(r.actions.len(), n * layout.act_bytes);
        assert_eq!((r.seeds.len(), r.selected.len()), (n, n));
        // What the hub read, encoded again, reads the same.
        let again = batch_codec::encode_request(
            &layout,
            r.header.seq,
            r.header.command,
            r.header.slot,
            &RequestBody {
                actions: Some(r.actions),
                selected: Some(&r.selected),
                seeds: &r.seeds,
                options: r.options.as_bytes(),
            },
        );
        let back =
            batch_codec::parse_request(&again, &layout).expect("a re-encoded request parses");
        assert_eq!(
            (back.actions, &back.seeds, &back.selected, back.options),
            (r.actions, &r.seeds, &r.selected, r.options)
        );
    }
    round_trip(&mut Unstructured::new(data));
});

/// A request drawn from the input, encoded as the client does: it parses to what was sent.
fn round_trip(u: &mut Unstructured<'_>) {
    let layout = Layout::new(below(u, MAX_ENVS + 1), below(u, MAX_VALUE + 1));
    let n = layout.num_envs;
    let commands = [
        command::RESET,
        command::STEP,
        command::RENDER,
        command::CLOSE,
    ];
    let cmd = commands[below(u, commands.len())];
    let (seq, slot): (u64, u32) = (u.arbitrary().unwrap_or(0), u.arbitrary().unwrap_or(0));
    let actions = bytes(u, n * layout.act_bytes);
    let selected: Vec<bool> = (0..n).map(|_| u.arbitrary().unwrap_or(true)).collect();
    let seeds: Vec<Option<u64>> = (0..n).map(|_| u.arbitrary().unwrap_or(None)).collect();
    let options: String = u.arbitrary().unwrap_or_default();
    let body = RequestBody {
        actions: Some(&actions),
        selected: Some(&selected),
        seeds: &seeds,
        options: options.as_bytes(),
    };
    let encoded = batch_codec::encode_request(&layout, seq, cmd, slot, &body);
    let r = batch_codec::parse_request(&encoded, &layout).expect("an encoded request parses");
    assert_eq!(
        (r.header.seq, r.header.command, r.header.slot),
        (seq, cmd, slot)
    );
    assert_eq!(r.actions, &actions[..]);
    assert_eq!(
        (r.selected, r.seeds, r.options),
        (selected, seeds, &options[..])
    );
}
