//! Opening the run's services (created beforehand by the orchestrator) and making ports on them,
//! with errors that name the service.

use crate::ipc::service_name;
use core::fmt::Debug;
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::time::Duration;

/// The iceoryx2 service flavour of every run (inter-process).
pub type Svc = ipc::Service;
/// A node of a run.
pub type RunNode = Node<Svc>;
/// Publisher of `T`.
pub type Pub<T> = Publisher<Svc, T, ()>;
/// Subscriber of `T`.
pub type Sub<T> = Subscriber<Svc, T, ()>;

/// Publisher on the existing service `name`.
pub fn publisher<T: Debug + ZeroCopySend + 'static>(
    node: &RunNode,
    name: &str,
) -> Result<Pub<T>, String> {
    let svc = node
        .service_builder(&service_name(name).map_err(|e| e.to_string())?)
        .publish_subscribe::<T>()
        .open()
        .map_err(|e| format!("cannot open service {name}: {e:?}"))?;
    svc.publisher_builder()
        .create()
        .map_err(|e| format!("cannot publish on {name}: {e:?}"))
}

/// Subscriber on the existing service `name`.
pub fn subscriber<T: Debug + ZeroCopySend + 'static>(
    node: &RunNode,
    name: &str,
) -> Result<Sub<T>, String> {
    let svc = node
        .service_builder(&service_name(name).map_err(|e| e.to_string())?)
        .publish_subscribe::<T>()
        .open()
        .map_err(|e| format!("cannot open service {name}: {e:?}"))?;
    svc.subscriber_builder()
        .create()
        .map_err(|e| format!("cannot subscribe to {name}: {e:?}"))
}

/// Publisher of slices of `T` (up to `max_len` elements) on the existing service `name`.
pub fn slice_publisher<T: Debug + ZeroCopySend + 'static>(
    node: &RunNode,
    name: &str,
    max_len: usize,
) -> Result<Pub<[T]>, String> {
    let svc = node
        .service_builder(&service_name(name).map_err(|e| e.to_string())?)
        .publish_subscribe::<[T]>()
        .open()
        .map_err(|e| format!("cannot open service {name}: {e:?}"))?;
    svc.publisher_builder()
        .initial_max_slice_len(max_len.max(1))
        .create()
        .map_err(|e| format!("cannot publish on {name}: {e:?}"))
}

/// Subscriber of slices of `T` on the existing service `name`.
pub fn slice_subscriber<T: Debug + ZeroCopySend + 'static>(
    node: &RunNode,
    name: &str,
) -> Result<Sub<[T]>, String> {
    let svc = node
        .service_builder(&service_name(name).map_err(|e| e.to_string())?)
        .publish_subscribe::<[T]>()
        .open()
        .map_err(|e| format!("cannot open service {name}: {e:?}"))?;
    svc.subscriber_builder()
        .create()
        .map_err(|e| format!("cannot subscribe to {name}: {e:?}"))
}

/// Notifier on the existing event service `name`.
pub fn notifier(node: &RunNode, name: &str) -> Result<Notifier<Svc>, String> {
    let svc = node
        .service_builder(&service_name(name).map_err(|e| e.to_string())?)
        .event()
        .open()
        .map_err(|e| format!("cannot open event {name}: {e:?}"))?;
    svc.notifier_builder()
        .create()
        .map_err(|e| format!("cannot notify {name}: {e:?}"))
}

/// The event a process sleeps on.
#[derive(Debug)]
pub struct Wake {
    listener: Listener<Svc>,
}

impl Wake {
    /// Listener on the existing event service `name`.
    pub fn open(node: &RunNode, name: &str) -> Result<Wake, String> {
        let svc = node
            .service_builder(&service_name(name).map_err(|e| e.to_string())?)
            .event()
            .open()
            .map_err(|e| format!("cannot open event {name}: {e:?}"))?;
        let listener = svc
            .listener_builder()
            .create()
            .map_err(|e| format!("cannot listen on {name}: {e:?}"))?;
        Ok(Wake { listener })
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
    pub fn wait(&self, timeout: Duration) -> Result<(), String> {
        let mut pending = false;
        match self.listener.try_wait(|_| pending = true) {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
            Err(e) => return Err(format!("event drain failed: {e:?}")),
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
                return Err(format!("event wait failed: {e}"));
            }
        }
        match self.listener.try_wait(|_| {}) {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
            Err(e) => Err(format!("event drain failed: {e:?}")),
        }
    }

    /// Busy-polls for a notification for up to `spin`, then sleeps as [`Wake::wait`] for the rest of
    /// `timeout`. With `spin` zero this is [`Wake::wait`].
    pub fn spin_then_wait(&self, spin: Duration, timeout: Duration) -> Result<(), String> {
        if !spin.is_zero() {
            let start = std::time::Instant::now();
            loop {
                let mut got = false;
                if let Err(e) = self.listener.try_wait(|_| got = true) {
                    return Err(format!("event poll failed: {e:?}"));
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

    /// Consumes pending notifications without sleeping.
    pub fn clear(&self) {
        let _ = self.listener.try_wait(|_| {});
    }
}

/// Notifies, ignoring failures (a peer that has gone away is detected by the orchestrator).
pub fn poke(n: &Notifier<Svc>) {
    let _ = n.notify();
}

/// Publishes a copy of `value`.
pub fn send<T: Debug + ZeroCopySend + Copy + 'static>(p: &Pub<T>, value: T) -> Result<(), String> {
    p.send_copy(value)
        .map(|_| ())
        .map_err(|e| format!("send failed: {e:?}"))
}
