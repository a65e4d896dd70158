//! iceoryx2 transports: publish-subscribe of `[u8]` slices plus an event service to wake the
//! receiver, waited on with the event listener itself ("event") or a WaitSet ("waitset"); or
//! publish-subscribe alone, busy-polled ("poll").
//!
//! Per case there are four services: `step` (plant -> agents), `reply` (agents -> plant) and one
//! event service for each direction. The plant process creates all of them, sized for the case,
//! before the agents start; agents only open them.

use super::link::{Link, Msg};
use formation_config::node::ipc::{self as fipc, Limits};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use std::io;
use std::time::Duration;

type Pubsub = publish_subscribe::PortFactory<ipc::Service, [u8], ()>;
type Event = event::PortFactory<ipc::Service>;

fn err(what: &str, e: impl std::fmt::Debug) -> io::Error {
    io::Error::other(format!("{what}: {e:?}"))
}

/// The four services of one case.
pub struct Services {
    step: Pubsub,
    reply: Pubsub,
    step_ev: Event,
    reply_ev: Event,
}

fn name(case: usize, what: &str) -> io::Result<ServiceName> {
    fipc::service_name(&format!("bench/{case}/{what}")).map_err(|e| err("service name", e))
}

impl Services {
    /// Creates the services of case `case` for a plant and `n` agents.
    pub fn create(node: &Node<ipc::Service>, case: usize, n: usize) -> io::Result<Self> {
        let limits = Limits::for_processes(n + 1);
        let pubsub = |what: &str| -> io::Result<Pubsub> {
            let b = node
                .service_builder(&name(case, what)?)
                .publish_subscribe::<[u8]>();
            fipc::pubsub_with_limits(b, &limits)
                .create()
                .map_err(|e| err("create publish-subscribe service", e))
        };
        let event = |what: &str| -> io::Result<Event> {
            let b = node.service_builder(&name(case, what)?).event();
            fipc::event_with_limits(b, &limits)
                .create()
                .map_err(|e| err("create event service", e))
        };
        Ok(Services {
            step: pubsub("step")?,
            reply: pubsub("reply")?,
            step_ev: event("step-ev")?,
            reply_ev: event("reply-ev")?,
        })
    }

    /// Opens the services of case `case` (created by the plant).
    pub fn open(node: &Node<ipc::Service>, case: usize) -> io::Result<Self> {
        let pubsub = |what: &str| -> io::Result<Pubsub> {
            node.service_builder(&name(case, what)?)
                .publish_subscribe::<[u8]>()
                .open()
                .map_err(|e| err("open publish-subscribe service", e))
        };
        let event = |what: &str| -> io::Result<Event> {
            node.service_builder(&name(case, what)?)
                .event()
                .open()
                .map_err(|e| err("open event service", e))
        };
        Ok(Services {
            step: pubsub("step")?,
            reply: pubsub("reply")?,
            step_ev: event("step-ev")?,
            reply_ev: event("reply-ev")?,
        })
    }
}

/// The ports of one process in a case.
pub struct Ports {
    publisher: Publisher<ipc::Service, [u8], ()>,
    subscriber: Subscriber<ipc::Service, [u8], ()>,
    notifier: Option<Notifier<ipc::Service>>,
    /// The event listener of this process's inbound direction.
    pub listener: Listener<ipc::Service>,
}

impl Ports {
    /// Ports of the plant (publishes steps, subscribes to replies). Without `notify` (busy-poll)
    /// no wake-up notifications are sent.
    pub fn plant(s: &Services, payload: usize, notify: bool) -> io::Result<Self> {
        Self::new(&s.step, &s.reply, &s.step_ev, &s.reply_ev, payload, notify)
    }

    /// Ports of an agent (subscribes to steps, publishes replies).
    pub fn agent(s: &Services, payload: usize, notify: bool) -> io::Result<Self> {
        Self::new(&s.reply, &s.step, &s.reply_ev, &s.step_ev, payload, notify)
    }

    fn new(
        out: &Pubsub,
        inbound: &Pubsub,
        out_ev: &Event,
        in_ev: &Event,
        payload: usize,
        notify: bool,
    ) -> io::Result<Self> {
        let publisher = out
            .publisher_builder()
            .initial_max_slice_len(payload)
            .create()
            .map_err(|e| err("create publisher", e))?;
        let subscriber = inbound
            .subscriber_builder()
            .create()
            .map_err(|e| err("create subscriber", e))?;
        let notifier = if notify {
            Some(
                out_ev
                    .notifier_builder()
                    .create()
                    .map_err(|e| err("create notifier", e))?,
            )
        } else {
            None
        };
        let listener = in_ev
            .listener_builder()
            .create()
            .map_err(|e| err("create listener", e))?;
        Ok(Ports {
            publisher,
            subscriber,
            notifier,
            listener,
        })
    }
}

/// A [`Link`] over [`Ports`], blocking on the listener or on a WaitSet the listener is attached to.
pub struct IoxLink<'a> {
    ports: &'a Ports,
    waitset: Option<&'a WaitSet<ipc::Service>>,
    from: u32,
    out: Vec<u8>,
}

impl<'a> IoxLink<'a> {
    /// A link sending as `from` with `payload`-byte messages; `waitset` (if any) must have
    /// `ports.listener` attached.
    pub fn new(
        ports: &'a Ports,
        waitset: Option<&'a WaitSet<ipc::Service>>,
        from: u32,
        payload: usize,
    ) -> Self {
        IoxLink {
            ports,
            waitset,
            from,
            out: vec![0u8; payload],
        }
    }
}

/// A WaitSet without iceoryx2's own signal handling.
pub fn waitset() -> io::Result<WaitSet<ipc::Service>> {
    WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| err("create waitset", e))
}

impl Link for IoxLink<'_> {
    fn send(&mut self, seq: u64) -> io::Result<()> {
        Msg {
            seq,
            from: self.from,
        }
        .encode(&mut self.out);
        let sample = self
            .ports
            .publisher
            .loan_slice_uninit(self.out.len())
            .map_err(|e| err("loan", e))?;
        sample
            .write_from_slice(&self.out)
            .send()
            .map_err(|e| err("send", e))?;
        if let Some(n) = &self.ports.notifier {
            n.notify().map_err(|e| err("notify", e))?;
        }
        Ok(())
    }

    fn try_recv(&mut self) -> io::Result<Option<Msg>> {
        match self.ports.subscriber.receive() {
            Ok(Some(sample)) => Ok(Msg::decode(sample.payload())),
            Ok(None) => Ok(None),
            Err(e) => Err(err("receive", e)),
        }
    }

    fn block_recv(&mut self, timeout: Duration) -> io::Result<Option<Msg>> {
        if let Some(m) = self.try_recv()? {
            return Ok(Some(m));
        }
        let listener = &self.ports.listener;
        match self.waitset {
            None => {
                // Collects (and so drains) every pending notification.
                listener
                    .timed_wait(|_| {}, timeout)
                    .map_err(|e| err("listener wait", e))?;
            }
            Some(ws) => {
                ws.wait_and_process_once_with_timeout(
                    |_| {
                        let _ = listener.try_wait(|_| {});
                        CallbackProgression::Continue
                    },
                    timeout,
                )
                .map_err(|e| err("waitset wait", e))?;
            }
        }
        self.try_recv()
    }
}
