//! Errors shared by the modules of this crate: a Zenoh operation that failed, named.

use std::error::Error;

/// A Zenoh operation that failed: which (`put on KEY`, `cannot subscribe to exits`) and Zenoh's
/// error.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {source}")]
pub struct ZenohError {
    /// The operation, with the key or service it was about.
    pub what: String,
    /// Zenoh's error.
    pub source: Box<dyn Error + Send + Sync>,
}

impl ZenohError {
    /// `what` failed with Zenoh's `e`.
    pub fn new(what: impl Into<String>, e: impl Into<Box<dyn Error + Send + Sync>>) -> ZenohError {
        ZenohError {
            what: what.into(),
            source: e.into(),
        }
    }
}

/// Implements `From<$t> for String`, so that callers that still pass errors on as text (the host
/// daemon and the run coordinator, moving to their own crates) keep using `?`.
macro_rules! into_string {
    ($($t:ty),*) => {
        $(impl From<$t> for String {
            fn from(e: $t) -> String {
                e.to_string()
            }
        })*
    };
}
pub(crate) use into_string;
