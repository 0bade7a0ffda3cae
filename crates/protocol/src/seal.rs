//! Sealed session messages: every request and response of a remote session carries an AEAD
//! tag (ChaCha20-Poly1305, `ring`) made with the session's own key, which the client and the
//! hub agree when it opens (the key exchange in `handshake`): it never travels.
//!
//! The nonce is the message's direction and sequence number, so a request can never pass for
//! a response, nor one step for another; the sequence number stays in clear (the first 8
//! bytes, which both messages start with) and is covered by the tag. A peer that sees the
//! traffic can neither write a request or an answer the other end accepts, nor replay one
//! (the hub takes each sequence number once, the client only the one it waits for).
//! Everything after the sequence number is encrypted as well (`docs/design/security.md`: the
//! measured cost and why).
//!
//! A key seals at most one message per direction and sequence number with a given content:
//! the hub answers a repeat of a request with the very bytes it sent the first time.

use ring::aead::{Aad, CHACHA20_POLY1305, LessSafeKey, NONCE_LEN, Nonce, UnboundKey};

/// Bytes of a session key.
pub const KEY_LEN: usize = 32;
/// Bytes a sealed message has more than its content (the tag, at its end).
pub const TAG_LEN: usize = 16;
/// Bytes of clear sequence number at the start of every message.
const SEQ_LEN: usize = 8;

/// Which way a message goes (part of its nonce).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Client to hub.
    Request = 1,
    /// Hub to client.
    Response = 2,
}

/// A session's secret key.
pub struct SessionKey(LessSafeKey);

impl std::fmt::Debug for SessionKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SessionKey(..)")
    }
}

/// Why a message was not accepted (it is dropped: never answered, never run).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unsealed {
    /// Shorter than a sequence number and a tag.
    TooShort,
    /// The tag does not match: not made with this key, for this direction and sequence
    /// number, or changed on the way.
    Forged,
}

impl SessionKey {
    /// The key of these bytes.
    pub fn new(bytes: &[u8; KEY_LEN]) -> SessionKey {
        SessionKey(LessSafeKey::new(
            UnboundKey::new(&CHACHA20_POLY1305, bytes).expect("a 32-byte key"),
        ))
    }

    /// The key written as 64 hex digits (as the open reply carries it); `None` if it is not.
    pub fn from_hex(hex: &str) -> Option<SessionKey> {
        if hex.len() != 2 * KEY_LEN || !hex.is_ascii() {
            return None;
        }
        let mut bytes = [0u8; KEY_LEN];
        for (i, b) in bytes.iter_mut().enumerate() {
            *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
        }
        Some(SessionKey::new(&bytes))
    }

    /// Seals `message` (which starts with its sequence number) in place: encrypts what
    /// follows the sequence number and appends the tag.
    pub fn seal(&self, direction: Direction, message: &mut Vec<u8>) {
        assert!(
            message.len() >= SEQ_LEN,
            "a message starts with its sequence number"
        );
        let (seq, body) = message.split_at_mut(SEQ_LEN);
        let seq: [u8; SEQ_LEN] = (&*seq).try_into().expect("8 bytes");
        let tag = self
            .0
            .seal_in_place_separate_tag(nonce(direction, &seq), Aad::from(seq), body)
            .expect("a message within ChaCha20-Poly1305's limits");
        message.extend_from_slice(tag.as_ref());
    }

    /// Opens a sealed `message` in place (its content stays, the tag is removed); its sequence
    /// number, or why it is not accepted (then `message` is garbage).
    pub fn open(&self, direction: Direction, message: &mut Vec<u8>) -> Result<u64, Unsealed> {
        if message.len() < SEQ_LEN + TAG_LEN {
            return Err(Unsealed::TooShort);
        }
        let seq: [u8; SEQ_LEN] = message[..SEQ_LEN].try_into().expect("8 bytes");
        let opened = self
            .0
            .open_in_place(
                nonce(direction, &seq),
                Aad::from(seq),
                &mut message[SEQ_LEN..],
            )
            .map_err(|_| Unsealed::Forged)?
            .len();
        message.truncate(SEQ_LEN + opened);
        Ok(u64::from_le_bytes(seq))
    }
}

fn nonce(direction: Direction, seq: &[u8; SEQ_LEN]) -> Nonce {
    let mut n = [0u8; NONCE_LEN];
    n[0] = direction as u8;
    n[NONCE_LEN - SEQ_LEN..].copy_from_slice(seq);
    Nonce::assume_unique_for_key(n)
}

/// The key as 64 hex digits.
pub fn to_hex(bytes: &[u8; KEY_LEN]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(seq: u64, body: &[u8]) -> Vec<u8> {
        let mut m = seq.to_le_bytes().to_vec();
        m.extend_from_slice(body);
        m
    }

    #[test]
    fn a_sealed_message_opens_only_with_its_key_direction_and_sequence_number() {
        let key = SessionKey::new(&[7; KEY_LEN]);
        let mut m = message(5, b"step these actions");
        key.seal(Direction::Request, &mut m);
        assert_eq!(m.len(), 8 + 18 + TAG_LEN);
        assert!(
            !m.windows(5).any(|w| w == b"these"),
            "the content travels encrypted"
        );
        let mut ok = m.clone();
        assert_eq!(key.open(Direction::Request, &mut ok), Ok(5));
        assert_eq!(ok, message(5, b"step these actions"));
        // Another key, the other direction, another sequence number, a flipped bit: refused.
        let other = SessionKey::new(&[8; KEY_LEN]);
        assert_eq!(
            other.open(Direction::Request, &mut m.clone()),
            Err(Unsealed::Forged)
        );
        assert_eq!(
            key.open(Direction::Response, &mut m.clone()),
            Err(Unsealed::Forged)
        );
        let mut renumbered = m.clone();
        renumbered[..8].copy_from_slice(&6u64.to_le_bytes());
        assert_eq!(
            key.open(Direction::Request, &mut renumbered),
            Err(Unsealed::Forged)
        );
        let mut flipped = m.clone();
        flipped[10] ^= 1;
        assert_eq!(
            key.open(Direction::Request, &mut flipped),
            Err(Unsealed::Forged)
        );
        assert_eq!(
            key.open(Direction::Request, &mut vec![0; 23]),
            Err(Unsealed::TooShort)
        );
        // An unsealed message of the right shape is refused too.
        let mut plain = message(5, &[0; 40]);
        assert_eq!(
            key.open(Direction::Request, &mut plain),
            Err(Unsealed::Forged)
        );
    }

    #[test]
    fn keys_travel_as_hex() {
        let bytes: [u8; KEY_LEN] = std::array::from_fn(|i| i as u8 * 7);
        let hex = to_hex(&bytes);
        let (a, b) = (SessionKey::new(&bytes), SessionKey::from_hex(&hex).unwrap());
        let mut m = message(1, b"x");
        a.seal(Direction::Response, &mut m);
        assert_eq!(b.open(Direction::Response, &mut m), Ok(1));
        for bad in [
            "",
            "zz",
            &hex[..62],
            &format!("{hex}00"),
            &hex.replace('0', "g"),
        ] {
            assert!(SessionKey::from_hex(bad).is_none(), "{bad}");
        }
    }

    /// The cost of sealing and opening (`cargo test --release -- --ignored seal_cost
    /// --nocapture`): per MiB, encrypted and authenticated only, for docs/design/security.md.
    #[test]
    #[ignore = "a measurement"]
    fn seal_cost() {
        let key = SessionKey::new(&[3; KEY_LEN]);
        for size in [1 << 10, 27 << 10, 1 << 20] {
            let rounds = ((64 << 20) / size).max(8);
            let mut m = message(1, &vec![1u8; size]);
            let t = std::time::Instant::now();
            for _ in 0..rounds {
                key.seal(Direction::Request, &mut m);
                key.open(Direction::Request, &mut m).unwrap();
            }
            let per = t.elapsed() / rounds as u32;
            // Authentication only: the whole message as associated data, nothing encrypted.
            let t = std::time::Instant::now();
            for _ in 0..rounds {
                let n = nonce(Direction::Request, &[0; 8]);
                let tag = key
                    .0
                    .seal_in_place_separate_tag(n, Aad::from(&m[..]), &mut [])
                    .unwrap();
                let mut t2 = tag.as_ref().to_vec();
                let n = nonce(Direction::Request, &[0; 8]);
                key.0.open_in_place(n, Aad::from(&m[..]), &mut t2).unwrap();
            }
            let auth = t.elapsed() / rounds as u32;
            println!(
                "{size} bytes: seal+open {per:?} ({:.2} ms/MiB); authenticate+verify only {auth:?} ({:.2} ms/MiB)",
                per.as_secs_f64() * 1e3 * (1 << 20) as f64 / size as f64,
                auth.as_secs_f64() * 1e3 * (1 << 20) as f64 / size as f64
            );
        }
    }
}
