//! How a session's key is agreed without it ever being sent: an X25519 key exchange whose
//! result only the client and the hub can compute, bound to the hub's identity.
//!
//! The client sends, with its open request, an ephemeral X25519 public key and its identity
//! (an Ed25519 public key of this client process) with a signature over the hub's name, the
//! exchange key and the time ([`ClientHello`]). The hub checks the signature and the time,
//! draws an ephemeral key of its own, and answers with its public half, its identity (a static
//! Ed25519 key kept in its user's private folder) and a signature over the transcript: the
//! hub's name, the session id, a digest of the open request as it arrived, both exchange keys
//! and its identity ([`HubHello`]). Both ends derive the session key with HKDF-SHA256 from the
//! X25519 shared secret, salted with the transcript. A peer that records every byte of the
//! link has the two public keys but neither private one; a peer that changes a byte of the
//! request or the reply makes the client's check of the hub's signature fail; a hub's identity
//! is pinned by its clients (trust on first use, `envhub-net`'s `known_hubs`).
//!
//! The client offers the ciphers it seals with, fastest on its CPU first; the hub takes the
//! client's first unless that is AES-256-GCM, which it lacks the instructions for, and ChaCha
//! is offered too ([`choose_cipher`]). Its choice is in the transcript and in the key's
//! derivation, and the offer is in the request the transcript covers, so a peer that strips
//! or changes either makes the open fail, and one key never serves two ciphers. A client that
//! offers nothing (envhub before the offer) gets ChaCha20-Poly1305 and the transcript of then.
//!
//! `ring` does all of it (it is the AEAD's crate already): `agreement` (X25519, whose private
//! keys it keeps ephemeral — hence a separate Ed25519 key for the hub's static identity, as
//! TLS 1.3 does), `hkdf`, `digest` and `signature` (Ed25519, keys stored as PKCS#8).

use crate::seal::{Cipher, KEY_LEN, SessionKey};
use ring::agreement::{self, EphemeralPrivateKey, UnparsedPublicKey, X25519};
use ring::rand::SystemRandom;
use ring::signature::{ED25519, Ed25519KeyPair, KeyPair};

/// An Ed25519 public key to verify with.
fn ed25519(key: [u8; PUBLIC_LEN]) -> ring::signature::UnparsedPublicKey<[u8; PUBLIC_LEN]> {
    ring::signature::UnparsedPublicKey::new(&ED25519, key)
}
use serde::{Deserialize, Serialize};

/// How far a client's clock may be from the hub's, in milliseconds: a hello older or newer
/// than this is refused (and one seen before within twice this is a replay).
pub const HELLO_FRESH_MS: u64 = 120_000;

/// Bytes of an X25519 or Ed25519 public key.
const PUBLIC_LEN: usize = 32;

/// What a client adds to its open request: its half of the key exchange and who it is.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClientHello {
    /// The client's ephemeral X25519 public key, 64 hex digits (one per open).
    pub exchange: String,
    /// The client's identity: an Ed25519 public key, 64 hex digits. Per-client limits count
    /// identities.
    pub identity: String,
    /// When the client sent it, in milliseconds since the Unix epoch.
    pub time_ms: u64,
    /// The identity's signature (128 hex digits) over the hub's name, `exchange` and
    /// `time_ms`: no peer can open sessions in another client's name.
    pub proof: String,
    /// The ciphers the client seals with, by [`Cipher::name`], its preferred first; none
    /// from a client older than the offer (it gets ChaCha20-Poly1305).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ciphers: Vec<String>,
}

/// What a hub adds to its open reply: its half of the key exchange, bound to its identity.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HubHello {
    /// The hub's ephemeral X25519 public key, 64 hex digits.
    pub exchange: String,
    /// The hub's identity: an Ed25519 public key, 64 hex digits (pinned by its clients).
    pub identity: String,
    /// The identity's signature (128 hex digits) over the transcript.
    pub proof: String,
    /// The cipher the hub picked from the client's offer ([`Cipher::name`]); absent when the
    /// client offered none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cipher: Option<String>,
}

/// An Ed25519 identity: a hub's (static, stored as PKCS#8) or a client process's.
pub struct Identity {
    pair: Ed25519KeyPair,
}

impl std::fmt::Debug for Identity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Identity({})", self.public_hex())
    }
}

impl Identity {
    /// A new identity's PKCS#8 document (what a hub stores).
    pub fn generate_pkcs8() -> Result<Vec<u8>, String> {
        Ed25519KeyPair::generate_pkcs8(&SystemRandom::new())
            .map(|d| d.as_ref().to_vec())
            .map_err(|_| "the OS random source failed".to_string())
    }

    /// The identity stored in `pkcs8`.
    pub fn from_pkcs8(pkcs8: &[u8]) -> Result<Identity, String> {
        Ed25519KeyPair::from_pkcs8(pkcs8)
            .map(|pair| Identity { pair })
            .map_err(|e| format!("not an Ed25519 key in PKCS#8: {e}"))
    }

    /// A new identity that lives as long as this value (a client process's).
    pub fn generate() -> Result<Identity, String> {
        Identity::from_pkcs8(&Identity::generate_pkcs8()?)
    }

    /// Its public key, 64 hex digits.
    pub fn public_hex(&self) -> String {
        hex(self.pair.public_key().as_ref())
    }

    fn sign(&self, message: &[u8]) -> String {
        hex(self.pair.sign(message).as_ref())
    }
}

/// A client's open in progress: the private half of its exchange key, used once.
pub struct PendingOpen {
    private: EphemeralPrivateKey,
    exchange: [u8; PUBLIC_LEN],
    offered: Vec<Cipher>,
}

impl std::fmt::Debug for PendingOpen {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PendingOpen(..)")
    }
}

/// A client's hello to hub `hub` at `time_ms`, offering `ciphers` (preferred first; none is
/// the hello of envhub before the offer, sealed with ChaCha20-Poly1305), and what it needs to
/// finish the exchange.
pub fn client_hello(
    identity: &Identity,
    hub: &str,
    time_ms: u64,
    ciphers: &[Cipher],
) -> Result<(ClientHello, PendingOpen), String> {
    let private = EphemeralPrivateKey::generate(&X25519, &SystemRandom::new())
        .map_err(|_| "the OS random source failed".to_string())?;
    let public = private
        .compute_public_key()
        .map_err(|_| "cannot compute an X25519 public key".to_string())?;
    let exchange: [u8; PUBLIC_LEN] = public.as_ref().try_into().expect("32-byte X25519 keys");
    let identity_key = identity.pair.public_key().as_ref();
    let proof = identity.sign(&hello_digest(hub, &exchange, identity_key, time_ms));
    Ok((
        ClientHello {
            exchange: hex(&exchange),
            identity: hex(identity_key),
            time_ms,
            proof,
            ciphers: ciphers.iter().map(|c| c.name().to_string()).collect(),
        },
        PendingOpen {
            private,
            exchange,
            offered: ciphers.to_vec(),
        },
    ))
}

/// The cipher a hub takes from a client's offer (names, preferred first), where `hardware_aes`
/// says whether the hub's CPU seals AES-256-GCM fast: the client's first, unless that is
/// AES-256-GCM without those instructions here and ChaCha20-Poly1305 is offered too. `None`
/// for an empty offer (an older client: ChaCha20-Poly1305 and the transcript of then). An
/// offer with a name that is no cipher, or twice the same, is refused, naming the valid ones.
pub fn choose_cipher(offer: &[String], hardware_aes: bool) -> Result<Option<Cipher>, String> {
    if offer.len() > Cipher::ALL.len() {
        return Err(format!(
            "an offer of {} ciphers (there are {})",
            offer.len(),
            Cipher::ALL.len()
        ));
    }
    let mut ciphers = Vec::with_capacity(offer.len());
    for name in offer {
        let cipher = Cipher::from_name(name).ok_or_else(|| {
            let valid: Vec<&str> = Cipher::ALL.iter().map(|c| c.name()).collect();
            format!(
                "an offer of cipher {name:?}, which is none of {}",
                valid.join(", ")
            )
        })?;
        if ciphers.contains(&cipher) {
            return Err(format!("an offer of cipher {name:?} twice"));
        }
        ciphers.push(cipher);
    }
    Ok(match ciphers.first() {
        None => None,
        Some(Cipher::Aes256Gcm) if !hardware_aes && ciphers.contains(&Cipher::ChaCha20Poly1305) => {
            Some(Cipher::ChaCha20Poly1305)
        }
        Some(&first) => Some(first),
    })
}

/// What a hub checks of a client's hello to it (`hub`) at its time `now_ms`: the keys are
/// keys, the signature is the identity's, the time is within [`HELLO_FRESH_MS`], the cipher
/// offer names ciphers. Returns the client's exchange key and the cipher
/// ([`choose_cipher`] on this CPU), or what is wrong.
pub fn check_client_hello(
    hub: &str,
    hello: &ClientHello,
    now_ms: u64,
) -> Result<([u8; PUBLIC_LEN], Option<Cipher>), String> {
    let cipher = choose_cipher(&hello.ciphers, Cipher::fastest_here() == Cipher::Aes256Gcm)?;
    let exchange =
        unhex::<PUBLIC_LEN>(&hello.exchange).ok_or("an exchange key that is not 64 hex digits")?;
    let identity = unhex::<PUBLIC_LEN>(&hello.identity)
        .ok_or("an identity that is not 64 lowercase hex digits")?;
    let proof = unhex::<64>(&hello.proof).ok_or("a proof that is not 128 hex digits")?;
    if hello.time_ms.abs_diff(now_ms) > HELLO_FRESH_MS {
        return Err(format!(
            "a hello sent {} s from this hub's clock (more than {} s: a replay, or a clock that is off)",
            (hello.time_ms as i128 - now_ms as i128) / 1000,
            HELLO_FRESH_MS / 1000
        ));
    }
    ed25519(identity)
        .verify(
            &hello_digest(hub, &exchange, &identity, hello.time_ms),
            &proof,
        )
        .map_err(|_| "a hello whose proof is not its identity's signature".to_string())?;
    Ok((exchange, cipher))
}

/// The hub's answer to a checked hello: its [`HubHello`] and the session's key. `request`:
/// the open request's bytes as they arrived (the transcript covers them); `cipher`: what
/// [`check_client_hello`] chose.
pub fn hub_answer(
    identity: &Identity,
    hub: &str,
    session: &str,
    request: &[u8],
    client_exchange: &[u8; PUBLIC_LEN],
    cipher: Option<Cipher>,
) -> Result<(HubHello, SessionKey), String> {
    let private = EphemeralPrivateKey::generate(&X25519, &SystemRandom::new())
        .map_err(|_| "the OS random source failed".to_string())?;
    let public = private
        .compute_public_key()
        .map_err(|_| "cannot compute an X25519 public key".to_string())?;
    let exchange: [u8; PUBLIC_LEN] = public.as_ref().try_into().expect("32-byte X25519 keys");
    let identity_key: [u8; PUBLIC_LEN] = identity
        .pair
        .public_key()
        .as_ref()
        .try_into()
        .expect("32-byte Ed25519 keys");
    let transcript = transcript(
        hub,
        session,
        request,
        client_exchange,
        &exchange,
        &identity_key,
        cipher,
    );
    let key = derive(private, client_exchange, &transcript, cipher)?;
    Ok((
        HubHello {
            exchange: hex(&exchange),
            identity: hex(&identity_key),
            proof: identity.sign(&transcript),
            cipher: cipher.map(|c| c.name().to_string()),
        },
        key,
    ))
}

impl PendingOpen {
    /// Finishes the exchange with hub `hub`'s answer for session `session` to the request
    /// sent as `request` (bytes): checks the hub's signature over the transcript and derives
    /// the session key. Returns the hub's identity (64 hex digits, for pinning) and the key.
    pub fn finish(
        self,
        hub: &str,
        session: &str,
        request: &[u8],
        answer: &HubHello,
    ) -> Result<(String, SessionKey), String> {
        let exchange = unhex::<PUBLIC_LEN>(&answer.exchange)
            .ok_or("an exchange key that is not 64 hex digits")?;
        let identity =
            unhex::<PUBLIC_LEN>(&answer.identity).ok_or("an identity that is not 64 hex digits")?;
        let proof = unhex::<64>(&answer.proof).ok_or("a proof that is not 128 hex digits")?;
        let cipher = match (&answer.cipher, self.offered.is_empty()) {
            (None, true) => None,
            (None, false) => {
                return Err("a reply that names no cipher, to a hello that offered some".into());
            }
            (Some(name), _) => Some(
                Cipher::from_name(name)
                    .filter(|c| self.offered.contains(c))
                    .ok_or_else(|| {
                        format!("a reply that picks cipher {name:?}, which was not offered")
                    })?,
            ),
        };
        let transcript = transcript(
            hub,
            session,
            request,
            &self.exchange,
            &exchange,
            &identity,
            cipher,
        );
        ed25519(identity).verify(&transcript, &proof).map_err(|_| {
            "a reply whose proof is not its identity's signature of this exchange (changed \
                 on the way, or not from the hub that holds that identity)"
                .to_string()
        })?;
        let key = derive(self.private, &exchange, &transcript, cipher)?;
        Ok((answer.identity.clone(), key))
    }
}

/// Exchange keys seen lately, so a replayed hello is refused (a bounded map; entries older
/// than twice [`HELLO_FRESH_MS`] are forgotten, since such a hello is refused by its time).
#[derive(Debug, Default)]
pub struct SeenHellos {
    seen: std::collections::HashMap<[u8; PUBLIC_LEN], u64>,
}

impl SeenHellos {
    /// The most hellos remembered: past it (after forgetting the old ones) new opens are
    /// refused until some age out.
    pub const MAX: usize = 65_536;

    /// Notes a hello's exchange key at `now_ms`; an error if it was seen (a replay) or the
    /// memory is full.
    pub fn note(&mut self, exchange: &[u8; PUBLIC_LEN], now_ms: u64) -> Result<(), String> {
        if self.seen.contains_key(exchange) {
            return Err("a hello seen before (a replay)".into());
        }
        if self.seen.len() >= Self::MAX {
            self.seen
                .retain(|_, t| now_ms.saturating_sub(*t) <= 2 * HELLO_FRESH_MS);
            if self.seen.len() >= Self::MAX {
                return Err("too many opens lately".into());
            }
        }
        self.seen.insert(*exchange, now_ms);
        Ok(())
    }
}

fn hello_digest(hub: &str, exchange: &[u8], identity: &[u8], time_ms: u64) -> [u8; 32] {
    digest(&[
        b"envhub client hello v1",
        hub.as_bytes(),
        exchange,
        identity,
        &time_ms.to_le_bytes(),
    ])
}

/// The transcript the hub signs and the key is salted with; with a chosen cipher (v2) it
/// ends with the cipher's name, without one (a client that offered none) it is v1's.
fn transcript(
    hub: &str,
    session: &str,
    request: &[u8],
    client_exchange: &[u8],
    hub_exchange: &[u8],
    hub_identity: &[u8],
    cipher: Option<Cipher>,
) -> [u8; 32] {
    let request = ring::digest::digest(&ring::digest::SHA256, request);
    let common = [
        hub.as_bytes(),
        session.as_bytes(),
        request.as_ref(),
        client_exchange,
        hub_exchange,
        hub_identity,
    ];
    match cipher {
        None => digest(&[&[b"envhub open v1".as_slice()], &common[..]].concat()),
        Some(c) => digest(
            &[
                &[b"envhub open v2".as_slice()],
                &common[..],
                &[c.name().as_bytes()],
            ]
            .concat(),
        ),
    }
}

/// SHA-256 of `parts`, each prefixed with its length (no two lists of parts collide).
fn digest(parts: &[&[u8]]) -> [u8; 32] {
    let mut context = ring::digest::Context::new(&ring::digest::SHA256);
    for part in parts {
        context.update(&(part.len() as u64).to_le_bytes());
        context.update(part);
    }
    context
        .finish()
        .as_ref()
        .try_into()
        .expect("32-byte digests")
}

/// The session key: HKDF-SHA256 of the X25519 shared secret, salted with the transcript,
/// for the cipher (named in the expansion's info, so a key is never one of two ciphers).
fn derive(
    private: EphemeralPrivateKey,
    peer: &[u8; PUBLIC_LEN],
    transcript: &[u8; 32],
    cipher: Option<Cipher>,
) -> Result<SessionKey, String> {
    struct Len;
    impl ring::hkdf::KeyType for Len {
        fn len(&self) -> usize {
            KEY_LEN
        }
    }
    agreement::agree_ephemeral(private, &UnparsedPublicKey::new(&X25519, peer), |shared| {
        let mut key = [0u8; KEY_LEN];
        let v2 = cipher.map(|c| [b"envhub session key v2 ".as_slice(), c.name().as_bytes()]);
        let info: &[&[u8]] = match &v2 {
            Some(parts) => parts,
            None => &[b"envhub session key v1"],
        };
        ring::hkdf::Salt::new(ring::hkdf::HKDF_SHA256, transcript)
            .extract(shared)
            .expand(info, Len)
            .and_then(|okm| okm.fill(&mut key))
            .map(|()| SessionKey::new(cipher.unwrap_or(Cipher::ChaCha20Poly1305), &key))
    })
    .map_err(|_| "an exchange key that gives no shared secret".to_string())?
    .map_err(|_| "the session key's derivation failed".to_string())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The bytes of `text`, exactly `2 * N` lowercase hex digits: one spelling per key, since
/// identities are counted by their text (`ABCD` or `+f` would be a second name for a key).
fn unhex<const N: usize>(text: &str) -> Option<[u8; N]> {
    let digit = |c: u8| match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        _ => None,
    };
    let text = text.as_bytes();
    if text.len() != 2 * N {
        return None;
    }
    let mut out = [0u8; N];
    for (i, byte) in out.iter_mut().enumerate() {
        *byte = (digit(text[2 * i])? << 4) | digit(text[2 * i + 1])?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::seal::Direction;

    const BOTH: [Cipher; 2] = [Cipher::Aes256Gcm, Cipher::ChaCha20Poly1305];

    fn exchange(hub: &str, request: &[u8]) -> (HubHello, SessionKey, PendingOpen, Identity) {
        exchange_offering(hub, request, &BOTH)
    }

    fn exchange_offering(
        hub: &str,
        request: &[u8],
        offer: &[Cipher],
    ) -> (HubHello, SessionKey, PendingOpen, Identity) {
        let client = Identity::generate().unwrap();
        let hub_id = Identity::generate().unwrap();
        let (hello, pending) = client_hello(&client, hub, 1_000_000, offer).unwrap();
        let (ex, cipher) = check_client_hello(hub, &hello, 1_000_500).unwrap();
        let (answer, key) = hub_answer(&hub_id, hub, "s1", request, &ex, cipher).unwrap();
        (answer, key, pending, hub_id)
    }

    fn opens(sealer: &SessionKey, opener: &SessionKey) -> bool {
        let mut m = 7u64.to_le_bytes().to_vec();
        m.extend_from_slice(b"observation");
        sealer.seal(Direction::Response, &mut m);
        opener.open(Direction::Response, &mut m).is_ok()
    }

    #[test]
    fn both_ends_derive_the_same_key_and_nothing_sent_is_it() {
        let (answer, hub_key, pending, hub_id) = exchange("lab", b"request");
        let (identity, client_key) = pending.finish("lab", "s1", b"request", &answer).unwrap();
        assert_eq!(identity, hub_id.public_hex());
        assert!(opens(&hub_key, &client_key));
        // Nothing that travelled is the key: not the exchange keys, identity or proof.
        for sent in [&answer.exchange, &answer.identity] {
            let bytes = unhex::<32>(sent).unwrap();
            for cipher in Cipher::ALL {
                assert!(!opens(&hub_key, &SessionKey::new(cipher, &bytes)));
            }
        }
    }

    #[test]
    fn each_offer_gives_both_ends_one_key_of_the_chosen_cipher() {
        let aes_here = Cipher::fastest_here() == Cipher::Aes256Gcm;
        for (offer, picked) in [
            (&[Cipher::ChaCha20Poly1305][..], Some("chacha20-poly1305")),
            (
                &[Cipher::ChaCha20Poly1305, Cipher::Aes256Gcm][..],
                Some("chacha20-poly1305"),
            ),
            (&[Cipher::Aes256Gcm][..], Some("aes-256-gcm")),
            (
                &BOTH[..],
                Some(if aes_here {
                    "aes-256-gcm"
                } else {
                    "chacha20-poly1305"
                }),
            ),
            // A client of before the offer: ChaCha20-Poly1305 and the v1 transcript, which
            // it still finishes.
            (&[][..], None),
        ] {
            let (answer, hub_key, pending, _) = exchange_offering("lab", b"request", offer);
            assert_eq!(answer.cipher.as_deref(), picked, "{offer:?}");
            let (_, client_key) = pending.finish("lab", "s1", b"request", &answer).unwrap();
            assert!(opens(&hub_key, &client_key), "{offer:?}");
            assert!(opens(&client_key, &hub_key), "{offer:?}");
            let other = SessionKey::new(
                if picked == Some("aes-256-gcm") {
                    Cipher::ChaCha20Poly1305
                } else {
                    Cipher::Aes256Gcm
                },
                &[0; KEY_LEN],
            );
            assert!(!opens(&other, &client_key));
        }
    }

    #[test]
    fn a_reply_that_changes_or_drops_the_cipher_fails_the_client_s_check() {
        // The other cipher of the offer (a downgrade), one not offered, none, garbage.
        let (answer, _, pending, _) = exchange_offering("lab", b"request", &BOTH);
        let swapped = HubHello {
            cipher: Some(
                if answer.cipher.as_deref() == Some("aes-256-gcm") {
                    "chacha20-poly1305"
                } else {
                    "aes-256-gcm"
                }
                .into(),
            ),
            ..answer
        };
        let err = pending
            .finish("lab", "s1", b"request", &swapped)
            .unwrap_err();
        assert!(err.contains("proof"), "{err}");
        let (answer, _, pending, _) =
            exchange_offering("lab", b"request", &[Cipher::ChaCha20Poly1305]);
        let unoffered = HubHello {
            cipher: Some("aes-256-gcm".into()),
            ..answer
        };
        let err = pending
            .finish("lab", "s1", b"request", &unoffered)
            .unwrap_err();
        assert!(err.contains("not offered"), "{err}");
        for cipher in [None, Some("rot13".to_string())] {
            let (answer, _, pending, _) = exchange("lab", b"request");
            let bad = HubHello { cipher, ..answer };
            assert!(pending.finish("lab", "s1", b"request", &bad).is_err());
        }
    }

    #[test]
    fn the_hub_takes_the_client_s_first_cipher_unless_it_lacks_aes_instructions() {
        let names = |cs: &[&str]| cs.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let aes = Some(Cipher::Aes256Gcm);
        let chacha = Some(Cipher::ChaCha20Poly1305);
        for hw in [true, false] {
            assert_eq!(choose_cipher(&[], hw), Ok(None));
            assert_eq!(choose_cipher(&names(&["aes-256-gcm"]), hw), Ok(aes));
            assert_eq!(
                choose_cipher(&names(&["chacha20-poly1305"]), hw),
                Ok(chacha)
            );
            assert_eq!(
                choose_cipher(&names(&["chacha20-poly1305", "aes-256-gcm"]), hw),
                Ok(chacha)
            );
        }
        let both = names(&["aes-256-gcm", "chacha20-poly1305"]);
        assert_eq!(choose_cipher(&both, true), Ok(aes));
        assert_eq!(choose_cipher(&both, false), Ok(chacha));
        let err = choose_cipher(&names(&["none"]), true).unwrap_err();
        assert!(
            err.contains("\"none\"") && err.contains("aes-256-gcm, chacha20-poly1305"),
            "{err}"
        );
        let err = choose_cipher(&names(&["aes-256-gcm", "aes-256-gcm"]), true).unwrap_err();
        assert!(err.contains("twice"), "{err}");
        let err = choose_cipher(&names(&["a", "b", "c"]), true).unwrap_err();
        assert!(err.contains("3 ciphers"), "{err}");
    }

    #[test]
    fn a_changed_request_session_or_reply_fails_the_client_s_check() {
        let (answer, _, pending, _) = exchange("lab", b"request");
        assert!(pending.finish("lab", "s1", b"requesT", &answer).is_err());
        let (answer, _, pending, _) = exchange("lab", b"request");
        assert!(pending.finish("lab", "s2", b"request", &answer).is_err());
        let (answer, _, pending, _) = exchange("lab", b"request");
        assert!(pending.finish("other", "s1", b"request", &answer).is_err());
        // Another identity's signature (an impostor who signs with its own key but claims
        // the hub's identity).
        let (mut answer, _, pending, _) = exchange("lab", b"request");
        let (other, _, _, _) = exchange("lab", b"request");
        answer.proof = other.proof;
        let err = pending
            .finish("lab", "s1", b"request", &answer)
            .unwrap_err();
        assert!(err.contains("proof"), "{err}");
        // Garbage in every field.
        let (answer, _, pending, _) = exchange("lab", b"request");
        let bad = HubHello {
            exchange: "zz".into(),
            ..answer
        };
        assert!(pending.finish("lab", "s1", b"request", &bad).is_err());
    }

    #[test]
    fn a_client_hello_is_checked_for_its_hub_signature_time_and_replay() {
        let client = Identity::generate().unwrap();
        let (hello, _) = client_hello(&client, "lab", 1_000_000, &BOTH).unwrap();
        assert!(check_client_hello("lab", &hello, 1_000_000).is_ok());
        assert!(check_client_hello("other", &hello, 1_000_000).is_err());
        let late = check_client_hello("lab", &hello, 1_000_000 + HELLO_FRESH_MS + 1).unwrap_err();
        assert!(late.contains("replay"), "{late}");
        // Another identity claimed with this proof.
        let other = Identity::generate().unwrap();
        let claimed = ClientHello {
            identity: other.public_hex(),
            ..hello.clone()
        };
        assert!(check_client_hello("lab", &claimed, 1_000_000).is_err());
        // The same key spelled another way (identities are counted by their text).
        for spelling in [
            hello.identity.to_uppercase(),
            format!("+{}", &hello.identity[1..]),
        ] {
            let respelled = ClientHello {
                identity: spelling,
                ..hello.clone()
            };
            let err = check_client_hello("lab", &respelled, 1_000_000).unwrap_err();
            assert!(err.contains("lowercase hex digits"), "{err}");
        }
        let mut seen = SeenHellos::default();
        let (ex, _) = check_client_hello("lab", &hello, 1_000_000).unwrap();
        seen.note(&ex, 1_000_000).unwrap();
        // An offer that names no cipher is refused, naming the valid ones.
        let odd = ClientHello {
            ciphers: vec!["des".into()],
            ..hello.clone()
        };
        let err = check_client_hello("lab", &odd, 1_000_000).unwrap_err();
        assert!(err.contains("aes-256-gcm"), "{err}");
        assert!(seen.note(&ex, 1_000_001).unwrap_err().contains("replay"));
    }
}
