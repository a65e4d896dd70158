//! The plant's ports.

use formation_config::node::error::{NodeError, PortError, PortErrorKind};
use formation_config::node::ports::{
    notifier, publisher, slice_publisher, subscriber, Input, Output, Pub, RunNode, Svc, Wake,
};
use formation_config::protocol::messages::{RunControl, RunProgress, RuntimeEvent, StepEntry};
use formation_config::protocol::services;
use formation_config::protocol::wire::{ControlCommand, FaultInjection, VehicleState};
use iceoryx2::port::notifier::Notifier;

/// Every port of the plant process.
pub struct Ports {
    pub control: Input<RunControl>,
    pub progress: Input<RunProgress>,
    pub faults: Input<FaultInjection>,
    /// Runtime events in (crashes, hangs, joins, take-down requests) and out (take-downs).
    pub events: Input<RuntimeEvent>,
    pub events_out: Output<RuntimeEvent>,
    pub commands: Vec<Input<ControlCommand>>,
    pub states: Vec<Output<VehicleState>>,
    pub steps: Pub<[StepEntry]>,
    pub agents_wake: Vec<Notifier<Svc>>,
    pub orchestrator_wake: Notifier<Svc>,
    pub wake: Wake,
}

impl Ports {
    /// Opens the services the orchestrator created and makes the plant's ports.
    pub fn open(node: &RunNode, n: usize) -> Result<Ports, NodeError> {
        Ok(Ports {
            control: subscriber(node, &services::CONTROL.named())?,
            progress: subscriber(node, &services::PROGRESS.named())?,
            faults: subscriber(node, &services::FAULT_INJECTION.named())?,
            events: subscriber(node, &services::RUNTIME_EVENTS.named())?,
            events_out: publisher(node, &services::RUNTIME_EVENTS.named())?,
            commands: (0..n)
                .map(|i| subscriber(node, &services::CONTROL_COMMAND.at(i)))
                .collect::<Result<_, _>>()?,
            states: (0..n)
                .map(|i| publisher(node, &services::VEHICLE_STATE.at(i)))
                .collect::<Result<_, _>>()?,
            steps: slice_publisher(node, &services::STEPS.named(), n)?,
            agents_wake: (0..n)
                .map(|i| notifier(node, &services::WAKE_AGENT.at(i)))
                .collect::<Result<_, _>>()?,
            orchestrator_wake: notifier(node, &services::WAKE_ORCHESTRATOR.named())?,
            wake: Wake::open(node, &services::WAKE_PLANT.named())?,
        })
    }

    /// Publishes the record of one step (N entries) to the orchestrator.
    pub fn publish_step(&self, entries: &[StepEntry]) -> Result<(), PortError> {
        let failed = |e: &dyn core::fmt::Debug| {
            PortError::new(services::STEPS.pattern, PortErrorKind::Send, e)
        };
        let sample = self
            .steps
            .loan_slice_uninit(entries.len())
            .map_err(|e| failed(&e))?;
        sample
            .write_from_fn(|i| entries[i])
            .send()
            .map(|_| ())
            .map_err(|e| failed(&e))
    }
}
