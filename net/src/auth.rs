//! Each run is its own security domain: the launching orchestrator makes a secret per run
//! ([`RunSecret::generate`], 32 bytes from the operating system's generator) and gives it to the
//! daemons of the run in its `Prepare` request; from it every party derives the run's keys
//! ([`RunKey`], HKDF-SHA256 with one label per use). Everything about the run then carries proof
//! of the secret, an HMAC-SHA256 tag (RustCrypto's `hmac`, `sha2` and `hkdf` crates):
//!
//! | what | key label | tag over |
//! |---|---|---|
//! | a request about the run (orchestrator -> daemon) | `request` | the daemon's name, a sequence number, the request's bytes |
//! | a daemon's reply to it | `reply` | the daemon's name, the request's sequence number, the reply's bytes |
//! | a bridge frame | `frame` | the destination host, the sender's sequence number, the frame's bytes |
//! | an exit report or forwarded checkpoint (daemon -> orchestrator) | `report` | the key it is put on, the sender's sequence number, its bytes |
//!
//! A tag is checked before anything in the message is parsed or acted on; a sequence number
//! seen before from the same sender is refused, so a captured message cannot be replayed. Who
//! may send what is checked after the tag (a frame's sending host must be a host of the run).
//! The tag binds the destination (a request for host b is refused by host c) and the key
//! expression (an exit report is not a checkpoint).

use hmac::{Hmac, Mac};
use sha2::Sha256;
use std::collections::BTreeSet;

type HmacSha256 = Hmac<Sha256>;

/// Bytes of a run's secret.
pub const SECRET_LEN: usize = 32;
/// Bytes of a tag (HMAC-SHA256, not truncated).
pub const TAG_LEN: usize = 32;
/// Bytes of the proof appended to a message: sequence number (u64 LE), then the tag.
pub const PROOF_LEN: usize = 8 + TAG_LEN;

/// A run's secret. Its `Debug` prints nothing of it; it travels only inside `Prepare`.
#[derive(Clone, PartialEq, Eq)]
pub struct RunSecret([u8; SECRET_LEN]);

impl std::fmt::Debug for RunSecret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RunSecret(..)")
    }
}

/// Why a secret could not be made or read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SecretError {
    /// The operating system's random generator failed.
    Random(String),
    /// Not 64 hexadecimal digits.
    Malformed,
}

impl std::fmt::Display for SecretError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SecretError::Random(e) => write!(f, "cannot make the run's secret: {e}"),
            SecretError::Malformed => f.write_str("the run's secret is not 64 hexadecimal digits"),
        }
    }
}

impl std::error::Error for SecretError {}

impl RunSecret {
    /// A new secret from the operating system's generator (`getrandom`).
    pub fn generate() -> Result<RunSecret, SecretError> {
        let mut b = [0u8; SECRET_LEN];
        getrandom::getrandom(&mut b).map_err(|e| SecretError::Random(e.to_string()))?;
        Ok(RunSecret(b))
    }

    /// Lower-case hexadecimal, as `Prepare` carries it.
    pub fn to_hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Reads [`RunSecret::to_hex`].
    pub fn from_hex(s: &str) -> Result<RunSecret, SecretError> {
        if s.len() != 2 * SECRET_LEN || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(SecretError::Malformed);
        }
        let mut b = [0u8; SECRET_LEN];
        for (i, out) in b.iter_mut().enumerate() {
            *out =
                u8::from_str_radix(&s[2 * i..2 * i + 2], 16).map_err(|_| SecretError::Malformed)?;
        }
        Ok(RunSecret(b))
    }

    /// The run's keys.
    pub fn keys(&self, run_id: &str) -> RunKey {
        let hk = hkdf::Hkdf::<Sha256>::new(Some(run_id.as_bytes()), &self.0);
        let derive = |label: &str| {
            let mut k = [0u8; 32];
            hk.expand(format!("formation/v3/{label}").as_bytes(), &mut k)
                .expect("32 bytes is a valid HKDF-SHA256 output length");
            k
        };
        RunKey {
            request: derive("request"),
            reply: derive("reply"),
            frame: derive("frame"),
            report: derive("report"),
        }
    }
}

impl serde::Serialize for RunSecret {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_hex())
    }
}

impl<'de> serde::Deserialize<'de> for RunSecret {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<RunSecret, D::Error> {
        let s = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        RunSecret::from_hex(&s).map_err(serde::de::Error::custom)
    }
}

/// What a message's proof is for (each its own key).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Purpose {
    /// A request about the run, to the named daemon.
    Request,
    /// A daemon's reply to a request.
    Reply,
    /// A bridge frame, to the named host.
    Frame,
    /// An exit report or checkpoint, on the named key expression.
    Report,
}

/// Why a message was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ProofError {
    /// Shorter than a proof.
    Missing,
    /// The tag does not match: not made with this run's secret, or altered.
    BadTag,
    /// A sequence number already seen (a replay).
    Replayed(u64),
}

impl std::fmt::Display for ProofError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ProofError::Missing => f.write_str("it carries no proof of the run's secret"),
            ProofError::BadTag => f.write_str("its proof of the run's secret is wrong"),
            ProofError::Replayed(s) => write!(f, "it repeats sequence number {s} (a replay)"),
        }
    }
}

impl std::error::Error for ProofError {}

/// The keys of one run (see the module documentation).
#[derive(Clone)]
pub struct RunKey {
    request: [u8; 32],
    reply: [u8; 32],
    frame: [u8; 32],
    report: [u8; 32],
}

impl std::fmt::Debug for RunKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RunKey(..)")
    }
}

impl RunKey {
    fn mac(&self, p: Purpose, to: &str, seq: u64) -> HmacSha256 {
        let key = match p {
            Purpose::Request => &self.request,
            Purpose::Reply => &self.reply,
            Purpose::Frame => &self.frame,
            Purpose::Report => &self.report,
        };
        let mut m = HmacSha256::new_from_slice(key).expect("HMAC takes a key of any length");
        m.update(&(to.len() as u32).to_le_bytes());
        m.update(to.as_bytes());
        m.update(&seq.to_le_bytes());
        m
    }

    /// Appends the proof (`seq`, tag) of `msg` for `p` to `to`.
    pub fn seal(&self, p: Purpose, to: &str, seq: u64, msg: &mut Vec<u8>) {
        let mut m = self.mac(p, to, seq);
        m.update(msg);
        let tag = m.finalize().into_bytes();
        msg.extend_from_slice(&seq.to_le_bytes());
        msg.extend_from_slice(&tag);
    }

    /// Checks the proof at the end of `sealed` for `p` to `to` (in constant time); the message
    /// without it and its sequence number. Nothing of the message is read before.
    pub fn open<'a>(
        &self,
        p: Purpose,
        to: &str,
        sealed: &'a [u8],
    ) -> Result<(&'a [u8], u64), ProofError> {
        let body_len = sealed
            .len()
            .checked_sub(PROOF_LEN)
            .ok_or(ProofError::Missing)?;
        let (body, proof) = sealed.split_at(body_len);
        let seq = u64::from_le_bytes(proof[..8].try_into().expect("8 bytes"));
        let mut m = self.mac(p, to, seq);
        m.update(body);
        m.verify_slice(&proof[8..])
            .map_err(|_| ProofError::BadTag)?;
        Ok((body, seq))
    }
}

/// The sequence numbers seen from one sender: a number seen before, or older than the
/// [`Replay::WINDOW`] numbers below the newest, is refused. Senders number their messages 1, 2,
/// 3, ...; several threads of one sender may deliver them slightly out of order.
#[derive(Debug, Default, Clone)]
pub struct Replay {
    newest: u64,
    seen: BTreeSet<u64>,
}

impl Replay {
    /// How far below the newest number a message may still arrive.
    pub const WINDOW: u64 = 1024;

    /// Accepts `seq` once.
    pub fn accept(&mut self, seq: u64) -> Result<(), ProofError> {
        let floor = self.newest.saturating_sub(Self::WINDOW);
        if seq == 0 || seq <= floor || !self.seen.insert(seq) {
            return Err(ProofError::Replayed(seq));
        }
        self.newest = self.newest.max(seq);
        let floor = self.newest.saturating_sub(Self::WINDOW);
        while self.seen.first().is_some_and(|&s| s <= floor) {
            self.seen.pop_first();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key() -> RunKey {
        RunSecret::from_hex(&"ab".repeat(32))
            .unwrap()
            .keys("c0ffee")
    }

    #[test]
    fn a_sealed_message_opens_only_with_the_runs_key_for_its_purpose_and_destination() {
        let k = key();
        let mut m = b"spawn agent 4".to_vec();
        k.seal(Purpose::Request, "b", 7, &mut m);
        assert_eq!(
            k.open(Purpose::Request, "b", &m),
            Ok((&b"spawn agent 4"[..], 7))
        );
        assert_eq!(
            k.open(Purpose::Request, "c", &m),
            Err(ProofError::BadTag),
            "another host"
        );
        assert_eq!(
            k.open(Purpose::Frame, "b", &m),
            Err(ProofError::BadTag),
            "another purpose"
        );
        let other = RunSecret::from_hex(&"cd".repeat(32))
            .unwrap()
            .keys("c0ffee");
        assert_eq!(
            other.open(Purpose::Request, "b", &m),
            Err(ProofError::BadTag),
            "another run"
        );
        let same_secret_other_run = RunSecret::from_hex(&"ab".repeat(32))
            .unwrap()
            .keys("c0ffef");
        assert_eq!(
            same_secret_other_run.open(Purpose::Request, "b", &m),
            Err(ProofError::BadTag)
        );
        for i in 0..m.len() {
            let mut x = m.clone();
            x[i] ^= 0x01;
            assert!(
                k.open(Purpose::Request, "b", &x).is_err(),
                "byte {i} flipped"
            );
        }
        assert_eq!(
            k.open(Purpose::Request, "b", &m[..20]),
            Err(ProofError::Missing)
        );
        assert_eq!(k.open(Purpose::Request, "b", &[]), Err(ProofError::Missing));
    }

    #[test]
    fn a_sequence_number_is_accepted_once_and_old_ones_are_refused() {
        let mut r = Replay::default();
        assert!(r.accept(0).is_err(), "0 is never sent");
        assert!(r.accept(1).is_ok());
        assert!(r.accept(3).is_ok());
        assert!(r.accept(2).is_ok(), "slightly out of order");
        assert_eq!(r.accept(3), Err(ProofError::Replayed(3)));
        assert!(r.accept(5000).is_ok());
        assert_eq!(
            r.accept(4),
            Err(ProofError::Replayed(4)),
            "below the window"
        );
        assert!(r.accept(4000).is_ok(), "within the window");
        assert!(r.seen.len() <= Replay::WINDOW as usize + 1);
    }

    #[test]
    fn a_secret_round_trips_through_hex_and_prints_nothing() {
        let s = RunSecret::generate().unwrap();
        assert_eq!(RunSecret::from_hex(&s.to_hex()).unwrap(), s);
        assert_ne!(RunSecret::generate().unwrap(), s);
        assert_eq!(format!("{s:?}"), "RunSecret(..)");
        assert_eq!(format!("{:?}", s.keys("a")), "RunKey(..)");
        assert_eq!(RunSecret::from_hex("zz"), Err(SecretError::Malformed));
        assert_eq!(
            RunSecret::from_hex(&"g".repeat(64)),
            Err(SecretError::Malformed)
        );
    }
}
