//! The per-field wire layout of every message: name, byte offset, Rust type and unit, for
//! `formation schema` and the client SDKs (`clients/`).
//!
//! Each message declares its table next to its struct with [`wire_fields!`]: the names, types and
//! units are kept by hand there, the offsets and sizes come from `core::mem::offset_of!` and
//! `size_of`. A field named or typed differently from the struct does not compile; a field left
//! out (or a new field not added) fails the test that every table tiles its struct exactly
//! (`every_wire_table_covers_its_struct_field_by_field`).

/// One field of a wire message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    /// Field name, as in the Rust struct.
    pub name: &'static str,
    /// Byte offset from the start of the message.
    pub offset: usize,
    /// Size in bytes.
    pub size: usize,
    /// Rust type: `u32`, `u64`, `f64`, `[f64; 3]`, `[[f64; 3]; 128]`, or another wire message.
    pub ty: &'static str,
    /// Unit (`s`, `m`, `rad/s`, ...), `-` for a pure number, an index or an enumeration.
    pub unit: &'static str,
}

/// A message with a field table.
pub trait WireLayout {
    /// Rust name of the type, without its module path.
    const NAME: &'static str;
    /// Its fields in declaration (and offset) order.
    const FIELDS: &'static [Field];
}

/// Declares the field table of a `#[repr(C)]` message:
/// `wire_fields!(VehicleState { step: u64 => "-", t: f64 => "s", ... });`
#[macro_export]
macro_rules! wire_fields {
    ($t:ident { $($f:ident : $ty:ty => $unit:literal),* $(,)? }) => {
        impl $crate::protocol::layout::WireLayout for $t {
            const NAME: &'static str = stringify!($t);
            const FIELDS: &'static [$crate::protocol::layout::Field] = &[
                $($crate::protocol::layout::Field {
                    name: stringify!($f),
                    offset: core::mem::offset_of!($t, $f),
                    size: core::mem::size_of::<$ty>(),
                    ty: stringify!($ty),
                    unit: $unit,
                }),*
            ];
        }
        // Each declared type is the field's type.
        const _: () = {
            $(
                #[allow(dead_code)]
                fn $f(m: &$t) -> &$ty {
                    &m.$f
                }
            )*
        };
    };
}

/// The layout of one wire type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TypeLayout {
    /// Rust name, without its module path.
    pub name: &'static str,
    /// Size in bytes.
    pub size: usize,
    /// Alignment in bytes.
    pub align: usize,
    /// Its fields.
    pub fields: &'static [Field],
}

impl TypeLayout {
    /// The layout of `T`.
    pub fn of<T: WireLayout>() -> TypeLayout {
        TypeLayout {
            name: T::NAME,
            size: size_of::<T>(),
            align: align_of::<T>(),
            fields: T::FIELDS,
        }
    }
}

use crate::protocol::messages::{
    Hello, InjectRequest, RunControl, RunProgress, RuntimeEvent, StepEntry,
};
use crate::protocol::wire::{
    AgentTelemetry, ControlCommand, ControllerTelemetry, DelayInjection, FaultInjection,
    NeighbourState, PlantTruth, ReferenceFrame, Traffic, TrafficEntry, VehicleState,
};

/// Every wire type: the messages of the services and the structs nested in them, each after the
/// types it contains.
pub fn every_type() -> [TypeLayout; 17] {
    [
        TypeLayout::of::<TrafficEntry>(),
        TypeLayout::of::<Traffic>(),
        TypeLayout::of::<VehicleState>(),
        TypeLayout::of::<NeighbourState>(),
        TypeLayout::of::<ReferenceFrame>(),
        TypeLayout::of::<ControllerTelemetry>(),
        TypeLayout::of::<ControlCommand>(),
        TypeLayout::of::<PlantTruth>(),
        TypeLayout::of::<FaultInjection>(),
        TypeLayout::of::<DelayInjection>(),
        TypeLayout::of::<AgentTelemetry>(),
        TypeLayout::of::<RunControl>(),
        TypeLayout::of::<RunProgress>(),
        TypeLayout::of::<Hello>(),
        TypeLayout::of::<StepEntry>(),
        TypeLayout::of::<InjectRequest>(),
        TypeLayout::of::<RuntimeEvent>(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Offsets increase, each field starts where the previous one ends (no field missing: repr(C)
    /// pads only to alignment, and every message pads explicitly with `_pad`), and the last one
    /// ends at the size of the struct.
    #[test]
    fn every_wire_table_covers_its_struct_field_by_field() {
        for t in every_type() {
            let mut end = 0;
            for f in t.fields {
                assert_eq!(f.offset, end, "{}.{} starts at {end}", t.name, f.name);
                end = f.offset + f.size;
            }
            assert_eq!(end, t.size, "{} ends at its size", t.name);
        }
    }

    #[test]
    fn every_nested_type_is_listed_before_the_types_that_contain_it() {
        let all = every_type();
        for (i, t) in all.iter().enumerate() {
            for f in t.fields {
                if f.ty.starts_with(|c: char| c.is_ascii_uppercase()) {
                    let j = all.iter().position(|x| x.name == f.ty);
                    assert!(j.is_some_and(|j| j < i), "{}.{}: {}", t.name, f.name, f.ty);
                }
            }
        }
    }

    #[test]
    fn a_field_table_gives_the_offset_type_and_unit_of_each_field() {
        let f = AgentTelemetry::FIELDS;
        assert_eq!(f[0].name, "step");
        let ctl = f
            .iter()
            .find(|f| f.name == "controller")
            .expect("controller");
        assert_eq!(
            ctl.offset,
            core::mem::offset_of!(AgentTelemetry, controller)
        );
        assert_eq!(ctl.ty, "ControllerTelemetry");
        assert_eq!(ctl.size, size_of::<ControllerTelemetry>());
        let t = f.iter().find(|f| f.name == "t").expect("t");
        assert_eq!((t.ty, t.unit, t.offset), ("f64", "s", 8));
        let off = ReferenceFrame::FIELDS
            .iter()
            .find(|f| f.name == "offset")
            .expect("offset");
        assert_eq!(off.ty, "[[f64; 3]; 128]");
    }
}
