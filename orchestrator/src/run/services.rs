//! Every service of a run, created by the orchestrator before any role process starts, by walking
//! the service table (`formation_config::protocol::services`) with limits sized for the run (limits
//! are fixed by the creator; the role processes only open them).

use formation_config::node::error::{PortError, PortErrorKind};
use formation_config::node::ipc::{event_with_limits, pubsub_with_limits, service_name};
use formation_config::node::ports::{RunNode, Svc};
use formation_config::protocol::services::{
    self, Event, Limits, Message, Named, Sizing, Slice, Topic, Visitor,
};
use std::any::Any;

/// The created services; they live as long as this value (the orchestrator keeps it for the run).
pub struct RunServices {
    _keep: Vec<Box<dyn Any>>,
}

/// Creates each service the table walk visits.
struct Creator<'a> {
    node: &'a RunNode,
    keep: Vec<Box<dyn Any>>,
}

fn created<S: 'static, E: std::fmt::Debug>(
    name: &str,
    r: Result<S, E>,
) -> Result<Box<dyn Any>, PortError> {
    r.map(|s| Box::new(s) as Box<dyn Any>)
        .map_err(|e| PortError::new(name, PortErrorKind::Create, e))
}

impl Visitor for Creator<'_> {
    type Error = PortError;

    fn topic<T: Message>(&mut self, s: Named<Topic<T>>, l: Limits) -> Result<(), PortError> {
        let sn =
            service_name(&s.name).map_err(|e| PortError::new(&s.name, PortErrorKind::Name, e))?;
        let builder =
            pubsub_with_limits(self.node.service_builder(&sn).publish_subscribe::<T>(), &l)
                .history_size(s.spec.history);
        self.keep.push(created(&s.name, builder.create())?);
        Ok(())
    }

    fn slices<T: Message>(
        &mut self,
        s: Named<Topic<T, Slice>>,
        l: Limits,
    ) -> Result<(), PortError> {
        let sn =
            service_name(&s.name).map_err(|e| PortError::new(&s.name, PortErrorKind::Name, e))?;
        let builder = pubsub_with_limits(
            self.node.service_builder(&sn).publish_subscribe::<[T]>(),
            &l,
        )
        .history_size(s.spec.history);
        self.keep.push(created(&s.name, builder.create())?);
        Ok(())
    }

    fn event(&mut self, s: Named<Event>, l: Limits) -> Result<(), PortError> {
        let sn =
            service_name(&s.name).map_err(|e| PortError::new(&s.name, PortErrorKind::Name, e))?;
        let r: Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, _> =
            event_with_limits(self.node.service_builder(&sn).event(), &l).create();
        self.keep.push(created(&s.name, r)?);
        Ok(())
    }
}

impl RunServices {
    /// Creates every service of a run sized by `sizing` (`Sizing::for_scenario`).
    pub fn create(node: &RunNode, sizing: Sizing) -> Result<RunServices, PortError> {
        let mut creator = Creator {
            node,
            keep: Vec::new(),
        };
        services::visit(&sizing, &mut creator)?;
        Ok(RunServices {
            _keep: creator.keep,
        })
    }
}
