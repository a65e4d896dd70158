//! Checkpoints of an agent's whole controller state (filters, adaptive estimates, RBFNN weights,
//! auxiliary states, fault identifier, delay histories) with serde + bincode, and the serde forms
//! of the fixed arrays longer than serde's own (32): a restarted agent process restores the latest
//! one (`restart_state = "warm"`, `docs/failures.md`).

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Why a checkpoint could not be written or read.
#[derive(Debug)]
pub enum CheckpointError {
    /// bincode could not encode the state.
    Encode(String),
    /// The bytes are not a checkpoint of this agent (another agent, another build, truncated).
    Decode(String),
}

impl std::fmt::Display for CheckpointError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CheckpointError::Encode(e) => write!(f, "cannot encode the checkpoint: {e}"),
            CheckpointError::Decode(e) => write!(f, "not a checkpoint of this agent: {e}"),
        }
    }
}

impl std::error::Error for CheckpointError {}

/// Encodes `value` with bincode's standard configuration.
pub fn encode<T: Serialize>(value: &T) -> Result<Vec<u8>, CheckpointError> {
    bincode::serde::encode_to_vec(value, bincode::config::standard())
        .map_err(|e| CheckpointError::Encode(e.to_string()))
}

/// Decodes a `T` from all of `bytes`.
pub fn decode<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<T, CheckpointError> {
    let (v, used) = bincode::serde::decode_from_slice(bytes, bincode::config::standard())
        .map_err(|e| CheckpointError::Decode(e.to_string()))?;
    if used != bytes.len() {
        return Err(CheckpointError::Decode(format!(
            "{} bytes left over of {}",
            bytes.len() - used,
            bytes.len()
        )));
    }
    Ok(v)
}

/// `[T; N]` of any length as a sequence.
pub mod array {
    use super::*;

    /// Serialises the array as a sequence.
    pub fn serialize<S: Serializer, T: Serialize, const N: usize>(
        a: &[T; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(a.iter())
    }

    /// Reads a sequence of exactly N elements.
    pub fn deserialize<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(
        d: D,
    ) -> Result<[T; N], D::Error> {
        let v: Vec<T> = Vec::deserialize(d)?;
        let len = v.len();
        v.try_into()
            .map_err(|_| D::Error::custom(format!("expected {N} elements, got {len}")))
    }
}

/// `[[f64; N]; M]` of any sizes as a sequence of sequences.
pub mod rows {
    use super::*;

    /// Serialises each row as a sequence.
    pub fn serialize<S: Serializer, const N: usize, const M: usize>(
        a: &[[f64; N]; M],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(a.iter().map(|r| &r[..]))
    }

    /// Reads M rows of N numbers.
    pub fn deserialize<'de, D: Deserializer<'de>, const N: usize, const M: usize>(
        d: D,
    ) -> Result<[[f64; N]; M], D::Error> {
        let v: Vec<Vec<f64>> = Vec::deserialize(d)?;
        let mut out = [[0.0; N]; M];
        if v.len() != M || v.iter().any(|r| r.len() != N) {
            return Err(D::Error::custom(format!("expected {M} rows of {N}")));
        }
        for (o, r) in out.iter_mut().zip(&v) {
            o.copy_from_slice(r);
        }
        Ok(out)
    }
}
