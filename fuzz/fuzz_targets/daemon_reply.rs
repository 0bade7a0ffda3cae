//! The hub daemon's replies as a client reads them (`parse_reply`): the `ok` value, the
//! daemon's error, or text; never a panic. A reply the daemon encodes reads back as sent.
#![no_main]

use envhub_protocol::daemon::{ReplyError, encode_reply, parse_reply};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(line) = std::str::from_utf8(data) else {
        return;
    };
    match parse_reply(line) {
        Ok(ok) => {
            let back = parse_reply(&encode_reply(&Ok(ok.clone()))).expect("an encoded ok");
            assert_eq!(back, ok);
        }
        Err(ReplyError::Error(e)) => {
            let text = e.to_string();
            match parse_reply(&encode_reply(&Err(e))) {
                Err(ReplyError::Error(back)) => assert_eq!(back.to_string(), text),
                other => panic!("an encoded error came back as {other:?}"),
            }
        }
        Err(ReplyError::Text(_) | ReplyError::Unreadable(_)) => {}
    }
});
