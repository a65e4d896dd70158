//! What two hosts must share before a run may span them: the protocol of this crate, the build of
//! the executable, and the layout of every wire type.

use serde::{Deserialize, Serialize};

/// Version of the orchestrator <-> daemon protocol ([`crate::proto`]) and the bridge's frame.
pub const PROTOCOL: u32 = 2;

/// A host's identity as compared at the handshake.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Identity {
    /// [`PROTOCOL`].
    pub protocol: u32,
    /// Package version plus a hash of the running executable's bytes (the same build on every host).
    pub build: String,
    /// Hash of the name, size, alignment and field table of every wire type
    /// (`formation_config::protocol::layout::every_type`).
    pub layout: String,
}

/// FNV-1a, 64 bits: stable across builds and machines (unlike `std`'s hasher).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The wire-layout hash of this build.
pub fn layout_hash() -> String {
    let text = format!("{:?}", formation_config::protocol::layout::every_type());
    format!("{:016x}", fnv1a(text.as_bytes()))
}

/// This process's identity; the build part hashes the executable file (`/proc/self/exe`), or an
/// override (`FORMATION_BUILD_ID`, for tests of a mismatch).
pub fn local() -> Identity {
    let build = match std::env::var("FORMATION_BUILD_ID") {
        Ok(v) if !v.is_empty() => v,
        _ => {
            let exe = std::fs::read("/proc/self/exe").unwrap_or_default();
            format!("{}+{:016x}", env!("CARGO_PKG_VERSION"), fnv1a(&exe))
        }
    };
    let protocol = std::env::var("FORMATION_NET_PROTOCOL")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(PROTOCOL);
    Identity {
        protocol,
        build,
        layout: layout_hash(),
    }
}

/// What differs between two identities, one phrase per item (empty: compatible).
pub fn differences(a: &Identity, b: &Identity) -> Vec<String> {
    let mut d = Vec::new();
    if a.protocol != b.protocol {
        d.push(format!("protocol version {} vs {}", a.protocol, b.protocol));
    }
    if a.build != b.build {
        d.push(format!("build {} vs {}", a.build, b.build));
    }
    if a.layout != b.layout {
        d.push(format!("wire layout {} vs {}", a.layout, b.layout));
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_identities_have_no_difference_and_each_field_is_named() {
        let a = Identity {
            protocol: 1,
            build: "0.1.0+aa".into(),
            layout: "ff".into(),
        };
        assert!(differences(&a, &a.clone()).is_empty());
        let b = Identity {
            protocol: 2,
            build: "0.1.0+bb".into(),
            layout: "ee".into(),
        };
        let d = differences(&a, &b);
        assert_eq!(d.len(), 3);
        assert!(d[0].starts_with("protocol version 1 vs 2"));
        assert!(d[1].contains("0.1.0+aa vs 0.1.0+bb"));
        assert!(d[2].starts_with("wire layout"));
    }

    #[test]
    fn the_layout_hash_is_stable_within_a_build() {
        assert_eq!(layout_hash(), layout_hash());
        assert_eq!(layout_hash().len(), 16);
    }
}
