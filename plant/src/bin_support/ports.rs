//! The plant's ports.

use formation_config::runtime::messages::{RunControl, RunProgress, StepEntry};
use formation_config::runtime::ports::{
    notifier, publisher, slice_publisher, subscriber, Pub, RunNode, Sub, Svc, Wake,
};
use formation_config::runtime::{self as rt};
use formation_config::services;
use formation_config::wire::{ControlCommand, FaultInjection, VehicleState};
use iceoryx2::port::notifier::Notifier;

/// Every port of the plant process.
pub struct Ports {
    pub control: Sub<RunControl>,
    pub progress: Sub<RunProgress>,
    pub faults: Sub<FaultInjection>,
    pub commands: Vec<Sub<ControlCommand>>,
    pub states: Vec<Pub<VehicleState>>,
    pub steps: Pub<[StepEntry]>,
    pub agents_wake: Vec<Notifier<Svc>>,
    pub orchestrator_wake: Notifier<Svc>,
    pub wake: Wake,
}

impl Ports {
    /// Opens the services the orchestrator created and makes the plant's ports.
    pub fn open(node: &RunNode, n: usize) -> Result<Ports, String> {
        Ok(Ports {
            control: subscriber(node, rt::CONTROL)?,
            progress: subscriber(node, rt::PROGRESS)?,
            faults: subscriber(node, services::FAULT_INJECTION)?,
            commands: (0..n)
                .map(|i| subscriber(node, &services::control_command(i)))
                .collect::<Result<_, _>>()?,
            states: (0..n)
                .map(|i| publisher(node, &services::vehicle_state(i)))
                .collect::<Result<_, _>>()?,
            steps: slice_publisher(node, rt::STEPS, n)?,
            agents_wake: (0..n)
                .map(|i| notifier(node, &rt::wake_agent(i)))
                .collect::<Result<_, _>>()?,
            orchestrator_wake: notifier(node, rt::WAKE_ORCHESTRATOR)?,
            wake: Wake::open(node, rt::WAKE_PLANT)?,
        })
    }

    /// Publishes the record of one step (N entries) to the orchestrator.
    pub fn publish_step(&self, entries: &[StepEntry]) -> Result<(), String> {
        let sample = self
            .steps
            .loan_slice_uninit(entries.len())
            .map_err(|e| format!("cannot loan a step record: {e:?}"))?;
        sample
            .write_from_fn(|i| entries[i])
            .send()
            .map(|_| ())
            .map_err(|e| format!("cannot send a step record: {e:?}"))
    }
}
