//! Every service of a run, created by the orchestrator before any role process starts, with limits
//! sized for N (limits are fixed by the creator; the role processes only open them).

use formation_config::ipc::{event_with_limits, pubsub_with_limits, service_name, Limits};
use formation_config::runtime::messages::{
    Hello, InjectRequest, RunControl, RunProgress, StepEntry,
};
use formation_config::runtime::ports::{RunNode, Svc};
use formation_config::runtime::{self as rt};
use formation_config::services;
use formation_config::wire::{
    AgentTelemetry, ControlCommand, DelayInjection, FaultInjection, NeighborState, ReferenceFrame,
    VehicleState,
};
use iceoryx2::prelude::*;
use std::any::Any;
use std::fmt::Debug;

/// The created services; they live as long as this value (the orchestrator keeps it for the run).
pub struct RunServices {
    _keep: Vec<Box<dyn Any>>,
}

fn limits(nodes: usize, senders: usize, receivers: usize, buffer: usize) -> Limits {
    Limits {
        nodes,
        senders,
        receivers,
        buffer,
    }
}

fn pubsub<T: Debug + ZeroCopySend + 'static>(
    node: &RunNode,
    name: &str,
    l: Limits,
) -> Result<Box<dyn Any>, String> {
    let sn = service_name(name).map_err(|e| e.to_string())?;
    let svc = pubsub_with_limits(node.service_builder(&sn).publish_subscribe::<T>(), &l)
        .create()
        .map_err(|e| format!("cannot create service {name}: {e:?}"))?;
    Ok(Box::new(svc))
}

fn slices<T: Debug + ZeroCopySend + 'static>(
    node: &RunNode,
    name: &str,
    l: Limits,
) -> Result<Box<dyn Any>, String> {
    let sn = service_name(name).map_err(|e| e.to_string())?;
    let svc = pubsub_with_limits(node.service_builder(&sn).publish_subscribe::<[T]>(), &l)
        .create()
        .map_err(|e| format!("cannot create service {name}: {e:?}"))?;
    Ok(Box::new(svc))
}

/// Agent telemetry: one publisher (the agent), up to `MAX_CLIENTS` inspectors, and a history of one
/// sample so that a subscriber that arrives late gets the latest one at once.
fn telemetry(node: &RunNode, i: usize, nodes: usize) -> Result<Box<dyn Any>, String> {
    let name = services::telemetry(i);
    let sn = service_name(&name).map_err(|e| e.to_string())?;
    let l = limits(nodes, 1, services::MAX_CLIENTS, 2);
    let svc = pubsub_with_limits(
        node.service_builder(&sn)
            .publish_subscribe::<AgentTelemetry>(),
        &l,
    )
    .history_size(1)
    .create()
    .map_err(|e| format!("cannot create service {name}: {e:?}"))?;
    Ok(Box::new(svc))
}

fn event(node: &RunNode, name: &str, l: Limits) -> Result<Box<dyn Any>, String> {
    let sn = service_name(name).map_err(|e| e.to_string())?;
    let svc: iceoryx2::service::port_factory::event::PortFactory<Svc> =
        event_with_limits(node.service_builder(&sn).event(), &l)
            .create()
            .map_err(|e| format!("cannot create event {name}: {e:?}"))?;
    Ok(Box::new(svc))
}

impl RunServices {
    /// Creates every service of a run with `n` agents. In realtime mode the plant does not wait for
    /// the recorder, so the step records get a deeper buffer.
    pub fn create(node: &RunNode, n: usize, realtime: bool) -> Result<RunServices, String> {
        let steps_buffer = if realtime {
            rt::REALTIME_STEPS_BUFFER
        } else {
            rt::STEPS_BUFFER
        };
        // Every process of the run may open any service: N agents, plant, leader, orchestrator,
        // and the client processes (`formation inspect`, `formation inject`).
        let nodes = n + 4 + services::MAX_CLIENTS;
        let clients = services::MAX_CLIENTS;
        let lock = rt::LOCKSTEP_BUFFER;
        let ctl = rt::CONTROL_BUFFER;
        let mut keep = vec![
            pubsub::<ReferenceFrame>(
                node,
                services::REFERENCE,
                limits(nodes, 1, n + 1, rt::REFERENCE_BUFFER),
            )?,
            pubsub::<FaultInjection>(node, services::FAULT_INJECTION, limits(nodes, 1, 1, ctl))?,
            pubsub::<DelayInjection>(node, services::DELAY_INJECTION, limits(nodes, 1, n, ctl))?,
            pubsub::<RunControl>(node, rt::CONTROL, limits(nodes, 1, n + 2, ctl))?,
            pubsub::<RunProgress>(node, rt::PROGRESS, limits(nodes, 1, 2, ctl))?,
            pubsub::<Hello>(node, rt::HELLO, limits(nodes, n + 2, 1, n + 2))?,
            slices::<StepEntry>(node, rt::STEPS, limits(nodes, 1, 1, steps_buffer))?,
            pubsub::<InjectRequest>(
                node,
                services::INJECT_REQUEST,
                limits(nodes, clients, 1, ctl),
            )?,
            event(
                node,
                rt::WAKE_ORCHESTRATOR,
                limits(nodes, n + 3 + clients, 1, 0),
            )?,
            event(node, rt::WAKE_PLANT, limits(nodes, n + 3, 1, 0))?,
            event(node, rt::WAKE_LEADER, limits(nodes, n + 3, 1, 0))?,
        ];
        for i in 0..n {
            keep.push(pubsub::<VehicleState>(
                node,
                &services::vehicle_state(i),
                limits(nodes, 1, 1, lock),
            )?);
            keep.push(pubsub::<NeighborState>(
                node,
                &services::neighbor_state(i),
                limits(nodes, 1, n.max(1), lock),
            )?);
            keep.push(pubsub::<ControlCommand>(
                node,
                &services::control_command(i),
                limits(nodes, 1, 1, lock),
            )?);
            keep.push(event(node, &rt::wake_agent(i), limits(nodes, n + 3, 1, 0))?);
            keep.push(telemetry(node, i, nodes)?);
        }
        Ok(RunServices { _keep: keep })
    }
}
