//! The ports of agent i.

use formation_config::runtime::messages::RunControl;
use formation_config::runtime::ports::{
    notifier, publisher, subscriber, Pub, RunNode, Sub, Svc, Wake,
};
use formation_config::runtime::{self as rt};
use formation_config::services;
use formation_config::wire::{
    AgentTelemetry, ControlCommand, DelayInjection, NeighborState, ReferenceFrame, VehicleState,
};
use iceoryx2::port::notifier::Notifier;

/// Every port of agent i.
pub struct Ports {
    pub control: Sub<RunControl>,
    pub delays: Sub<DelayInjection>,
    pub reference: Sub<ReferenceFrame>,
    pub state: Sub<VehicleState>,
    /// One per neighbour, in `neighbours` order.
    pub shares_in: Vec<Sub<NeighborState>>,
    pub share_out: Pub<NeighborState>,
    pub command: Pub<ControlCommand>,
    /// Live samples for `formation inspect` (never waited on).
    pub telemetry: Pub<AgentTelemetry>,
    pub plant_wake: Notifier<Svc>,
    /// One per neighbour, in `neighbours` order.
    pub neighbours_wake: Vec<Notifier<Svc>>,
    pub wake: Wake,
}

impl Ports {
    /// Opens the services the orchestrator created and makes agent i's ports.
    pub fn open(node: &RunNode, i: usize, neighbours: &[usize]) -> Result<Ports, String> {
        Ok(Ports {
            control: subscriber(node, rt::CONTROL)?,
            delays: subscriber(node, services::DELAY_INJECTION)?,
            reference: subscriber(node, services::REFERENCE)?,
            state: subscriber(node, &services::vehicle_state(i))?,
            shares_in: neighbours
                .iter()
                .map(|&j| subscriber(node, &services::neighbor_state(j)))
                .collect::<Result<_, _>>()?,
            share_out: publisher(node, &services::neighbor_state(i))?,
            command: publisher(node, &services::control_command(i))?,
            telemetry: publisher(node, &services::telemetry(i))?,
            plant_wake: notifier(node, rt::WAKE_PLANT)?,
            neighbours_wake: neighbours
                .iter()
                .map(|&j| notifier(node, &rt::wake_agent(j)))
                .collect::<Result<_, _>>()?,
            wake: Wake::open(node, &rt::wake_agent(i))?,
        })
    }
}
