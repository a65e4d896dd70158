//! Wire values a client printed, read back and checked against a run's outputs.

use formation_config::protocol::wire::VehicleState;
use formation_runtime::record::csv::Column;
use formation_runtime::record::table::Trajectory;
use std::collections::HashMap;

/// The wire struct `T` whose bytes a client printed in hex (`"raw"` of its JSON line: exact floats,
/// whatever a JSON parser rounds).
pub fn from_raw<T: Copy>(v: &serde_json::Value) -> T {
    let hex = v["raw"].as_str().expect("raw bytes");
    let bytes: Vec<u8> = (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex"))
        .collect();
    assert_eq!(
        bytes.len(),
        size_of::<T>(),
        "the client's struct has the Rust size"
    );
    // SAFETY: the length is checked; T is a #[repr(C)] wire struct of u32, u64 and f64 fields (and
    // nested such structs), for which every bit pattern is a valid value.
    unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<T>()) }
}

/// The rows of `trajectory.csv` by (1-based agent, step).
pub fn rows_by_agent_and_step(tr: &Trajectory) -> HashMap<(usize, u64), &[f64]> {
    tr.rows()
        .iter()
        .map(|r| {
            (
                (
                    tr.value(r, Column::Agent) as usize,
                    tr.value(r, Column::Step) as u64,
                ),
                r.as_slice(),
            )
        })
        .collect()
}

/// Asserts that state `s` equals its recorded `row`, float for float (position, velocity,
/// attitude, rate).
pub fn assert_state_is_row(tr: &Trajectory, row: &[f64], s: &VehicleState) {
    for (values, cols) in [
        (s.position, [Column::Px, Column::Py, Column::Pz]),
        (s.velocity, [Column::Vx, Column::Vy, Column::Vz]),
        (s.attitude, [Column::Phi, Column::Theta, Column::Psi]),
        (s.rate, [Column::P, Column::Q, Column::R]),
    ] {
        for (k, col) in cols.iter().enumerate() {
            assert_eq!(
                values[k],
                tr.value(row, *col),
                "{} of agent {} at {}",
                col.name(),
                s.agent + 1,
                s.step
            );
        }
    }
}
