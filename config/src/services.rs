//! Service names. Every run lives under its own iceoryx2 prefix (`formation_<run id>_`), so concurrent
//! runs never see each other; the names below are relative to that prefix.

/// iceoryx2 global prefix of a run: `fm<run_id>_` (short: it becomes part of file names in /dev/shm).
pub fn run_prefix(run_id: &str) -> String {
    format!("fm{run_id}_")
}

/// Leader -> agents: [`crate::wire::ReferenceFrame`].
pub const REFERENCE: &str = "formation/reference";
/// Orchestrator -> plant: [`crate::wire::FaultInjection`].
pub const FAULT_INJECTION: &str = "formation/inject/fault";
/// Orchestrator -> agents: [`crate::wire::DelayInjection`].
pub const DELAY_INJECTION: &str = "formation/inject/delay";

/// Plant -> agent i: [`crate::wire::VehicleState`].
pub fn vehicle_state(i: usize) -> String {
    format!("formation/agent/{i}/state")
}

/// Agent i -> neighbours: [`crate::wire::NeighborState`].
pub fn neighbor_state(i: usize) -> String {
    format!("formation/agent/{i}/share")
}

/// Agent i -> plant: [`crate::wire::ControlCommand`].
pub fn control_command(i: usize) -> String {
    format!("formation/agent/{i}/command")
}

/// Agent i telemetry for `formation inspect`.
pub fn telemetry(i: usize) -> String {
    format!("formation/agent/{i}/telemetry")
}

/// `formation inject` -> orchestrator: [`crate::runtime::messages::InjectRequest`].
pub const INJECT_REQUEST: &str = "formation/inject/request";

/// Most concurrent client processes (`formation inspect`, `ps`, `inject`) a run admits.
pub const MAX_CLIENTS: usize = 8;
