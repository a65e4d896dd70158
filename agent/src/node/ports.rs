//! The ports of agent i.

use formation_config::node::error::NodeError;
use formation_config::node::ports::{
    notifier, publisher, subscriber, Input, Output, RunNode, Svc, Wake,
};
use formation_config::protocol::messages::{RunControl, RuntimeEvent};
use formation_config::protocol::services;
use formation_config::protocol::wire::{
    AgentTelemetry, ControlCommand, DelayInjection, NeighbourState, ReferenceFrame, VehicleState,
};
use iceoryx2::port::notifier::Notifier;

/// Every port of agent i.
pub struct Ports {
    pub control: Input<RunControl>,
    pub delays: Input<DelayInjection>,
    /// Runtime events (crashes, hangs, links, losses, agents taken down or taking over).
    pub events: Input<RuntimeEvent>,
    pub reference: Input<ReferenceFrame>,
    pub state: Input<VehicleState>,
    /// One per neighbour, in `neighbours` order.
    pub shares_in: Vec<Input<NeighbourState>>,
    pub share_out: Output<NeighbourState>,
    pub command: Output<ControlCommand>,
    /// Live samples for `formation inspect` (never waited on).
    pub telemetry: Output<AgentTelemetry>,
    pub plant_wake: Notifier<Svc>,
    /// One per neighbour, in `neighbours` order.
    pub neighbours_wake: Vec<Notifier<Svc>>,
    pub wake: Wake,
}

impl Ports {
    /// Opens the services the orchestrator created and makes agent i's ports.
    pub fn open(node: &RunNode, i: usize, neighbours: &[usize]) -> Result<Ports, NodeError> {
        Ok(Ports {
            control: subscriber(node, &services::CONTROL.named())?,
            delays: subscriber(node, &services::DELAY_INJECTION.named())?,
            events: subscriber(node, &services::RUNTIME_EVENTS.named())?,
            reference: subscriber(node, &services::REFERENCE.named())?,
            state: subscriber(node, &services::VEHICLE_STATE.at(i))?,
            shares_in: neighbours
                .iter()
                .map(|&j| subscriber(node, &services::NEIGHBOUR_STATE.at(j)))
                .collect::<Result<_, _>>()?,
            share_out: publisher(node, &services::NEIGHBOUR_STATE.at(i))?,
            command: publisher(node, &services::CONTROL_COMMAND.at(i))?,
            telemetry: publisher(node, &services::TELEMETRY.at(i))?,
            plant_wake: notifier(node, &services::WAKE_PLANT.named())?,
            neighbours_wake: neighbours
                .iter()
                .map(|&j| notifier(node, &services::WAKE_AGENT.at(j)))
                .collect::<Result<_, _>>()?,
            wake: Wake::open(node, &services::WAKE_AGENT.at(i))?,
        })
    }
}
