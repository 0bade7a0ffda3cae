//! Requests to the hub daemon as it reads them from a client's connection: lines bounded by
//! `read_line_bounded`, each checked by `Request::parse`. A request the client encodes
//! reads back as the same request (`encode(parse(encode(x))) == encode(x)`).
#![no_main]

use envhub_protocol::daemon::{Request, read_line_bounded};
use libfuzzer_sys::fuzz_target;

/// A small bound, so the fuzzer reaches the overlong-line path with small inputs.
const MAX_LINE: usize = 4096;

fuzz_target!(|data: &[u8]| {
    let mut reader = std::io::Cursor::new(data);
    let mut line = String::new();
    // Each line takes at least one byte: the loop ends.
    while let Ok(n) = read_line_bounded(&mut reader, MAX_LINE, &mut line) {
        if n == 0 {
            break;
        }
        assert!(n <= MAX_LINE && line.len() == n);
        if let Ok(request) = Request::parse(&line) {
            let encoded = request.encode();
            let again = Request::parse(&encoded)
                .unwrap_or_else(|e| panic!("an encoded {} request fails: {e}", request.op()));
            assert_eq!(again.encode(), encoded);
        }
    }
});
