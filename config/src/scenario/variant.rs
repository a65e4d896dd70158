//! Controller variants selectable per run.

use serde::{Deserialize, Serialize};

/// Which controller the agents run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
#[repr(u32)]
pub enum Variant {
    /// The paper's cascade: NTDPC with RBFNN + BLF-based AFTAC.
    #[default]
    Proposed = 0,
    /// The same without the RBFNN term (Fig. 6 comparison).
    NoRbfnn = 1,
    /// Adaptive fault-tolerant attitude control without barrier terms (stands in for [51], Fig. 9).
    Unconstrained = 2,
}

impl Variant {
    /// The name used on the command line and in `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Proposed => "proposed",
            Variant::NoRbfnn => "no-rbfnn",
            Variant::Unconstrained => "unconstrained",
        }
    }

    /// Parses a command-line name.
    pub fn parse(s: &str) -> Option<Variant> {
        match s {
            "proposed" => Some(Variant::Proposed),
            "no-rbfnn" => Some(Variant::NoRbfnn),
            "unconstrained" => Some(Variant::Unconstrained),
            _ => None,
        }
    }

    /// Every variant.
    pub const ALL: [Variant; 3] = [Variant::Proposed, Variant::NoRbfnn, Variant::Unconstrained];

    /// Decodes the wire representation.
    pub fn from_u32(v: u32) -> Option<Variant> {
        Variant::ALL.into_iter().find(|x| *x as u32 == v)
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
