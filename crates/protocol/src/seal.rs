//! Sealed session messages: every request and response of a remote session carries an AEAD
//! tag (AES-256-GCM or ChaCha20-Poly1305, `ring`; [`Cipher`]) made with the session's own key,
//! which the client and the hub agree when it opens (the key exchange in `handshake`, which
//! also picks the cipher): it never travels.
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

use ring::aead::{
    AES_256_GCM, Aad, Algorithm, CHACHA20_POLY1305, LessSafeKey, NONCE_LEN, Nonce, UnboundKey,
};

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

/// The AEAD a session seals with. Both take 256-bit keys, 96-bit nonces and give 16-byte
/// tags, so only the algorithm differs; the client offers them fastest first, the hub picks
/// one and the key exchange covers its choice (`handshake`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cipher {
    /// About three times ChaCha20-Poly1305's speed on a CPU with AES and carry-less multiply
    /// instructions (x86-64's AES-NI and PCLMULQDQ, ARMv8's AES and PMULL), several times
    /// slower without them.
    Aes256Gcm,
    /// Fast everywhere in software; what a client that offers nothing (older envhub) gets.
    ChaCha20Poly1305,
}

impl Cipher {
    /// Every cipher, in no order of preference.
    pub const ALL: [Cipher; 2] = [Cipher::Aes256Gcm, Cipher::ChaCha20Poly1305];

    /// Its name on the wire.
    pub fn name(self) -> &'static str {
        match self {
            Cipher::Aes256Gcm => "aes-256-gcm",
            Cipher::ChaCha20Poly1305 => "chacha20-poly1305",
        }
    }

    /// The cipher of a wire name.
    pub fn from_name(name: &str) -> Option<Cipher> {
        Cipher::ALL.into_iter().find(|c| c.name() == name)
    }

    /// What this machine seals fastest: AES-256-GCM where the CPU has AES instructions.
    pub fn fastest_here() -> Cipher {
        if hardware_aes() {
            Cipher::Aes256Gcm
        } else {
            Cipher::ChaCha20Poly1305
        }
    }

    fn algorithm(self) -> &'static Algorithm {
        match self {
            Cipher::Aes256Gcm => &AES_256_GCM,
            Cipher::ChaCha20Poly1305 => &CHACHA20_POLY1305,
        }
    }
}

/// Whether this CPU has the instructions AES-GCM is fast with (`ring` uses them when present).
fn hardware_aes() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("aes")
            && std::arch::is_x86_feature_detected!("pclmulqdq")
    }
    #[cfg(target_arch = "aarch64")]
    {
        std::arch::is_aarch64_feature_detected!("aes")
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    {
        false
    }
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
    /// The key of these bytes, for `cipher`.
    pub fn new(cipher: Cipher, bytes: &[u8; KEY_LEN]) -> SessionKey {
        SessionKey(LessSafeKey::new(
            UnboundKey::new(cipher.algorithm(), bytes).expect("a 32-byte key"),
        ))
    }

    /// The ChaCha20-Poly1305 key written as 64 hex digits; `None` if it is not.
    pub fn from_hex(hex: &str) -> Option<SessionKey> {
        if hex.len() != 2 * KEY_LEN || !hex.is_ascii() {
            return None;
        }
        let mut bytes = [0u8; KEY_LEN];
        for (i, b) in bytes.iter_mut().enumerate() {
            *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
        }
        Some(SessionKey::new(Cipher::ChaCha20Poly1305, &bytes))
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
            .expect("a message within the AEAD's limits (64 GiB)");
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
        for cipher in Cipher::ALL {
            opens_only_with_its_key_direction_and_sequence_number(cipher);
        }
    }

    #[test]
    fn a_key_opens_nothing_sealed_by_the_other_cipher_and_names_travel() {
        let bytes = [9; KEY_LEN];
        let aes = SessionKey::new(Cipher::Aes256Gcm, &bytes);
        let chacha = SessionKey::new(Cipher::ChaCha20Poly1305, &bytes);
        let mut m = message(3, b"observations");
        aes.seal(Direction::Response, &mut m);
        assert_eq!(
            chacha.open(Direction::Response, &mut m.clone()),
            Err(Unsealed::Forged)
        );
        assert_eq!(aes.open(Direction::Response, &mut m), Ok(3));
        for c in Cipher::ALL {
            assert_eq!(Cipher::from_name(c.name()), Some(c));
        }
        assert_eq!(Cipher::from_name("AES-256-GCM"), None);
        assert_eq!(Cipher::from_name("none"), None);
    }

    fn opens_only_with_its_key_direction_and_sequence_number(cipher: Cipher) {
        let key = SessionKey::new(cipher, &[7; KEY_LEN]);
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
        let other = SessionKey::new(cipher, &[8; KEY_LEN]);
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
        let (a, b) = (
            SessionKey::new(Cipher::ChaCha20Poly1305, &bytes),
            SessionKey::from_hex(&hex).unwrap(),
        );
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
    /// --nocapture`): per MiB, encrypted and authenticated only, per cipher, for
    /// docs/design/security.md.
    #[test]
    #[ignore = "a measurement"]
    fn seal_cost() {
        println!("fastest here: {}", Cipher::fastest_here().name());
        for cipher in Cipher::ALL {
            seal_cost_of(cipher);
        }
    }

    fn seal_cost_of(cipher: Cipher) {
        let key = SessionKey::new(cipher, &[3; KEY_LEN]);
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
                "{} {size} bytes: seal+open {per:?} ({:.2} ms/MiB); authenticate+verify only {auth:?} ({:.2} ms/MiB)",
                cipher.name(),
                per.as_secs_f64() * 1e3 * (1 << 20) as f64 / size as f64,
                auth.as_secs_f64() * 1e3 * (1 << 20) as f64 / size as f64
            );
        }
    }
}
