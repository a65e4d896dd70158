//! `Wake::wait` never sleeps through a notification, even when notifiers race with its drain.
//!
//! Without the drain before the sleep (see `Wake::wait`), this test lost a wake-up in about one
//! run in two (one in a million notifications); the lockstep then stalled for the 25-100 ms
//! timeouts of its processes about once in 15 runs of 20 000 steps.

use formation_config::node::ipc::{self, event_with_limits, Limits};
use formation_config::node::ports::{notifier, poke, Wake};
use formation_config::protocol::services::{run_prefix, WAKE_PLANT};
use iceoryx2::prelude::ServiceName;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Notifiers (like the agents waking the plant) and notifications each sends.
const NOTIFIERS: usize = 4;
const ROUNDS: u64 = 250_000;
/// The listener's wait timeout. A wait that lasts this long while a "sample" is unread slept
/// through its notification until the timeout: a lost wake-up. (Normal wake-ups take microseconds;
/// a descheduled thread on a loaded 2-core machine can take hundreds of milliseconds, which is why
/// the wall-clock bound is the timeout itself and the notifiers wait longer than it.)
const WAIT: Duration = Duration::from_secs(2);

#[test]
fn a_notification_racing_with_the_listeners_drain_still_wakes_it() {
    let prefix = run_prefix(&format!("w{}t", std::process::id()));
    // The plant's wake-up event of the service table (created here with test limits).
    let name = WAKE_PLANT.pattern;
    let node = ipc::node(&prefix, "creator").expect("node");
    let limits = Limits {
        nodes: NOTIFIERS + 2,
        senders: NOTIFIERS,
        receivers: 1,
        buffer: 1,
    };
    let _svc = event_with_limits(
        node.service_builder(&ServiceName::new(name).unwrap())
            .event(),
        &limits,
    )
    .create()
    .expect("event service");

    // `published` stands for samples: a notifier counts one up, then notifies; the listener
    // acknowledges what it has seen after each wake-up.
    let published = Arc::new(AtomicU64::new(0));
    let seen = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicBool::new(false));
    let listening = Arc::new(AtomicBool::new(false));
    let listener = {
        let (prefix, published, seen, done, listening) = (
            prefix.clone(),
            published.clone(),
            seen.clone(),
            done.clone(),
            listening.clone(),
        );
        std::thread::spawn(move || {
            let node = ipc::node(&prefix, "listener").expect("node");
            let wake = Wake::open(&node, &WAKE_PLANT.named()).expect("listener");
            listening.store(true, Ordering::SeqCst);
            let mut lost = 0;
            while !done.load(Ordering::SeqCst) {
                let before = published.load(Ordering::SeqCst);
                let t0 = Instant::now();
                wake.wait(WAIT).expect("wait");
                let after = published.load(Ordering::SeqCst);
                // A long sleep while samples were (or became) unread: it slept through a
                // notification.
                if t0.elapsed() >= WAIT && (after > before || before > seen.load(Ordering::SeqCst))
                {
                    lost += 1;
                }
                seen.store(after, Ordering::SeqCst);
            }
            lost
        })
    };
    // Notifiers only reach listeners that exist: start once the listener is there.
    while !listening.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(1));
    }
    let notifiers: Vec<_> = (0..NOTIFIERS)
        .map(|i| {
            let (prefix, published, seen) = (prefix.clone(), published.clone(), seen.clone());
            std::thread::spawn(move || {
                let node = ipc::node(&prefix, &format!("notifier{i}")).expect("node");
                let n = notifier(&node, &WAKE_PLANT.named()).expect("notifier");
                for _ in 0..ROUNDS {
                    let mine = published.fetch_add(1, Ordering::SeqCst) + 1;
                    poke(&n);
                    // Like an agent waiting for its next state: until the listener has seen it.
                    let t0 = Instant::now();
                    while seen.load(Ordering::SeqCst) < mine && t0.elapsed() < 2 * WAIT {
                        std::thread::yield_now();
                    }
                }
            })
        })
        .collect();
    for n in notifiers {
        n.join().expect("notifier");
    }
    done.store(true, Ordering::SeqCst);
    // Wake the listener a last time, from a fresh notifier.
    let n = notifier(&node, &WAKE_PLANT.named()).expect("notifier");
    poke(&n);
    let lost = listener.join().expect("listener");
    drop(n);
    drop(_svc);
    drop(node);
    let _ = ipc::remove_residue(&prefix);
    assert_eq!(
        lost,
        0,
        "{lost} wake-ups lost in {} notifications",
        NOTIFIERS as u64 * ROUNDS
    );
}
