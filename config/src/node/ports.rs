//! Opening the run's services (created beforehand by the orchestrator) and making ports on them,
//! with errors that name the service.

use super::error::{PortError, PortErrorKind};
use crate::node::ipc::service_name;
use crate::protocol::services::{Event, Message, Named, Slice, Topic};
use core::fmt::Debug;
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use std::time::Duration;

/// The iceoryx2 service flavour of every run (inter-process).
pub type Svc = ipc::Service;
/// A node of a run.
pub type RunNode = Node<Svc>;
/// Publisher of `T`.
pub type Pub<T> = Publisher<Svc, T, ()>;
/// Subscriber of `T`.
pub type Sub<T> = Subscriber<Svc, T, ()>;

fn sname(name: &str) -> Result<ServiceName, PortError> {
    service_name(name).map_err(|e| PortError::new(name, PortErrorKind::Name, e))
}

fn open_topic<T: Message>(
    node: &RunNode,
    name: &str,
) -> Result<PortFactory<Svc, T, ()>, PortError> {
    node.service_builder(&sname(name)?)
        .publish_subscribe::<T>()
        .open()
        .map_err(|e| PortError::new(name, PortErrorKind::Open, e))
}

fn open_slices<T: Message>(
    node: &RunNode,
    name: &str,
) -> Result<PortFactory<Svc, [T], ()>, PortError> {
    node.service_builder(&sname(name)?)
        .publish_subscribe::<[T]>()
        .open()
        .map_err(|e| PortError::new(name, PortErrorKind::Open, e))
}

fn open_event(
    node: &RunNode,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, PortError> {
    node.service_builder(&sname(name)?)
        .event()
        .open()
        .map_err(|e| PortError::new(name, PortErrorKind::Open, e))
}

/// A publisher that knows its service's name (for its errors).
#[derive(Debug)]
pub struct Output<T: Message> {
    name: String,
    port: Pub<T>,
}

impl<T: Message> Output<T> {
    /// Publishes a copy of `value`.
    pub fn send(&self, value: T) -> Result<(), PortError> {
        self.port
            .send_copy(value)
            .map(|_| ())
            .map_err(|e| PortError::new(&self.name, PortErrorKind::Send, e))
    }

    /// The service name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl<T: Message> std::ops::Deref for Output<T> {
    type Target = Pub<T>;
    fn deref(&self) -> &Pub<T> {
        &self.port
    }
}

/// A subscriber that knows its service's name (for its errors).
#[derive(Debug)]
pub struct Input<T: Message> {
    name: String,
    port: Sub<T>,
}

impl<T: Message> Input<T> {
    /// The next sample, if any.
    pub fn receive(&self) -> Result<Option<Sample<Svc, T, ()>>, PortError> {
        self.port
            .receive()
            .map_err(|e| PortError::new(&self.name, PortErrorKind::Receive, e))
    }

    /// The service name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl<T: Message> std::ops::Deref for Input<T> {
    type Target = Sub<T>;
    fn deref(&self) -> &Sub<T> {
        &self.port
    }
}

/// Publisher on an existing service of the table.
pub fn publisher<T: Message>(
    node: &RunNode,
    svc: &Named<Topic<T>>,
) -> Result<Output<T>, PortError> {
    let port = open_topic::<T>(node, &svc.name)?
        .publisher_builder()
        .create()
        .map_err(|e| PortError::new(&svc.name, PortErrorKind::Port, e))?;
    Ok(Output {
        name: svc.name.clone(),
        port,
    })
}

/// Subscriber on an existing service of the table.
pub fn subscriber<T: Message>(
    node: &RunNode,
    svc: &Named<Topic<T>>,
) -> Result<Input<T>, PortError> {
    let port = open_topic::<T>(node, &svc.name)?
        .subscriber_builder()
        .create()
        .map_err(|e| PortError::new(&svc.name, PortErrorKind::Port, e))?;
    Ok(Input {
        name: svc.name.clone(),
        port,
    })
}

/// Publisher of slices of `T` (up to `max_len` elements) on an existing service of the table.
pub fn slice_publisher<T: Message>(
    node: &RunNode,
    svc: &Named<Topic<T, Slice>>,
    max_len: usize,
) -> Result<Pub<[T]>, PortError> {
    open_slices::<T>(node, &svc.name)?
        .publisher_builder()
        .initial_max_slice_len(max_len.max(1))
        .create()
        .map_err(|e| PortError::new(&svc.name, PortErrorKind::Port, e))
}

/// Subscriber of slices of `T` on an existing service of the table.
pub fn slice_subscriber<T: Message>(
    node: &RunNode,
    svc: &Named<Topic<T, Slice>>,
) -> Result<Sub<[T]>, PortError> {
    open_slices::<T>(node, &svc.name)?
        .subscriber_builder()
        .create()
        .map_err(|e| PortError::new(&svc.name, PortErrorKind::Port, e))
}

/// Notifier on an existing event service of the table.
pub fn notifier(node: &RunNode, svc: &Named<Event>) -> Result<Notifier<Svc>, PortError> {
    open_event(node, &svc.name)?
        .notifier_builder()
        .create()
        .map_err(|e| PortError::new(&svc.name, PortErrorKind::Port, e))
}

/// The event a process sleeps on.
#[derive(Debug)]
pub struct Wake {
    name: String,
    listener: Listener<Svc>,
}

impl Wake {
    /// Listener on an existing event service of the table.
    pub fn open(node: &RunNode, svc: &Named<Event>) -> Result<Wake, PortError> {
        let listener = open_event(node, &svc.name)?
            .listener_builder()
            .create()
            .map_err(|e| PortError::new(&svc.name, PortErrorKind::Port, e))?;
        Ok(Wake {
            name: svc.name.clone(),
            listener,
        })
    }

    /// Sleeps until notified or `timeout`, consuming every pending notification. The caller then
    /// drains every subscriber that may have new samples (notifications coalesce). A signal (e.g.
    /// SIGTERM) ends the sleep early without an error; the caller checks its flags.
    ///
    /// The sleep is one `ppoll(2)` on the listener's socket, then a non-blocking drain
    /// (`try_wait`). iceoryx2's own `timed_wait` switches the socket between blocking and
    /// non-blocking mode and sets a receive timeout on every call (seven system calls per wake-up
    /// instead of three here, measured with `strace -c`); on a 2-core machine where a lockstep step
    /// is a handful of wake-ups, that difference is on the critical path (docs/runtime.md).
    ///
    /// Before sleeping, a non-blocking drain: a notifier sends no datagram while the listener's
    /// shared state says "notified", and a drain racing with a notifier can consume its datagram
    /// before that notifier marks the state notified. The state then says notified with an empty
    /// socket, every later notification is swallowed, and a bare `ppoll` would sleep through them
    /// until the timeout (seen: one 25-100 ms stall in ~15 lockstep runs of 20 000 steps). The
    /// racing notifier's event is always seen by that drain, so returning whenever it reports an
    /// event, and sleeping only after a drain that reported none (which also resets the state),
    /// loses nothing.
    pub fn wait(&self, timeout: Duration) -> Result<(), PortError> {
        let mut pending = false;
        match self.listener.try_wait(|_| pending = true) {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
            Err(e) => return Err(self.error(e)),
        }
        if pending {
            return Ok(());
        }
        // SAFETY: the descriptor belongs to the listener, which outlives this call; it is only
        // polled here, never closed or read.
        let fd = unsafe { self.listener.file_descriptor().native_handle() };
        let mut pfd = libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        };
        let ts = libc::timespec {
            tv_sec: timeout.as_secs().min(i32::MAX as u64) as libc::time_t,
            tv_nsec: timeout.subsec_nanos() as libc::c_long,
        };
        // SAFETY: one valid pollfd, a valid timespec, no signal mask change.
        let r = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
        if r < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(self.error(e));
            }
        }
        match self.listener.try_wait(|_| {}) {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
            Err(e) => Err(self.error(e)),
        }
    }

    /// Busy-polls for a notification for up to `spin`, then sleeps as [`Wake::wait`] for the rest of
    /// `timeout`. With `spin` zero this is [`Wake::wait`].
    pub fn spin_then_wait(&self, spin: Duration, timeout: Duration) -> Result<(), PortError> {
        if !spin.is_zero() {
            let start = std::time::Instant::now();
            loop {
                let mut got = false;
                if let Err(e) = self.listener.try_wait(|_| got = true) {
                    return Err(self.error(e));
                }
                if got {
                    return Ok(());
                }
                let spent = start.elapsed();
                if spent >= spin || spent >= timeout {
                    return self.wait(timeout.saturating_sub(spent));
                }
                std::hint::spin_loop();
            }
        }
        self.wait(timeout)
    }

    fn error(&self, e: impl Debug) -> PortError {
        PortError::new(&self.name, PortErrorKind::Wait, e)
    }

    /// Consumes pending notifications without sleeping.
    pub fn clear(&self) {
        let _ = self.listener.try_wait(|_| {});
    }
}

/// Notifies, ignoring failures (a peer that has gone away is detected by the orchestrator).
pub fn poke(n: &Notifier<Svc>) {
    let _ = n.notify();
}

/// Publishes a copy of `value` on `p`.
pub fn send<T: Message>(p: &Output<T>, value: T) -> Result<(), PortError> {
    p.send(value)
}
