//! Which services of the typed service table cross hosts for a placement, and in which direction.
//!
//! Plant, leader, orchestrator and clients live on the launching host; agent i on its placed
//! host. A service is forwarded from every host that has a sender to every other host that has a
//! receiver. For the table of `formation_config::protocol::services` no host of any placement is
//! both a forwarding source and a forwarding sink of one service (every service has a single
//! sending host or a single receiving host), so a bridge never re-forwards its own samples
//! ([`Placement::route`] refuses a placement where it would).

use formation_config::protocol::services::{Party, Scope};
use std::collections::BTreeSet;

/// Where each process of a run lives.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// Host of agent i (0-based).
    pub agent_hosts: Vec<String>,
    /// The launching host: plant, leader, orchestrator, clients.
    pub launcher: String,
    /// For agent i, the agents that have it as a neighbour (0-based).
    pub neighbours: Vec<Vec<usize>>,
}

/// What one host's bridge does with one service.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Route {
    /// Hosts this host forwards the service to (it has a sender, they have receivers).
    pub out_to: Vec<String>,
    /// This host receives the service from another host (it has a receiver, another has a sender).
    pub inbound: bool,
}

impl Route {
    /// Nothing to do on this host.
    pub fn is_idle(&self) -> bool {
        self.out_to.is_empty() && !self.inbound
    }
}

/// The 0-based agent index in a per-agent service name (`formation/agent/3/state` for the
/// pattern `formation/agent/{i}/state` is 3).
pub fn agent_index(pattern: &str, name: &str) -> Option<usize> {
    let (head, tail) = pattern.split_once("{i}")?;
    let mid = name.strip_prefix(head)?.strip_suffix(tail)?;
    mid.parse().ok()
}

impl Placement {
    /// Neighbour lists from the scenario's undirected edges (1-based in the scenario).
    pub fn neighbours_of(
        n: usize,
        edges: impl IntoIterator<Item = (usize, usize)>,
    ) -> Vec<Vec<usize>> {
        let mut v = vec![Vec::new(); n];
        for (a, b) in edges {
            if a >= 1 && b >= 1 && a <= n && b <= n && a != b {
                v[a - 1].push(b - 1);
                v[b - 1].push(a - 1);
            }
        }
        v.iter_mut().for_each(|x| {
            x.sort_unstable();
            x.dedup()
        });
        v
    }

    /// Every host of the run, launcher first.
    pub fn hosts(&self) -> Vec<String> {
        let mut v = vec![self.launcher.clone()];
        for h in &self.agent_hosts {
            if !v.contains(h) {
                v.push(h.clone());
            }
        }
        v
    }

    /// Agents placed on `host`.
    pub fn agents_on(&self, host: &str) -> Vec<usize> {
        (0..self.agent_hosts.len())
            .filter(|&i| self.agent_hosts[i] == host)
            .collect()
    }

    /// The host that takes over the agents of a lost host: the launcher. It is always up while
    /// the run is (the run ends with it), holds the plant every step goes through and the
    /// forwarded checkpoints, and is the hub of the star topology, so the moved agents add no
    /// network hop to anyone's traffic.
    pub fn takeover_host(&self) -> &str {
        &self.launcher
    }

    /// The placement once `lost` is gone: its agents move to [`Placement::takeover_host`];
    /// returns it with the moved agents (0-based, ascending). `Err` for the launcher itself (the
    /// run ends with it) or a host the placement does not use (already handled).
    pub fn after_loss(&self, lost: &str) -> Result<(Placement, Vec<usize>), PlanError> {
        if lost == self.launcher {
            return Err(PlanError::LauncherLost(lost.to_string()));
        }
        let moved = self.agents_on(lost);
        if moved.is_empty() {
            return Err(PlanError::NoAgentOn(lost.to_string()));
        }
        let mut next = self.clone();
        for &i in &moved {
            next.agent_hosts[i] = self.takeover_host().to_string();
        }
        Ok((next, moved))
    }

    /// The placement the bridges work with when the hosts in `colocated` share the launcher's
    /// `/dev/shm` ([`crate::colocate`]): their agents open the launcher's services directly, so
    /// data-plane wise they are on the launcher and nothing is forwarded to or from those hosts.
    /// Daemons still start and report their agents (the control placement is `self`).
    pub fn data_plane<S: AsRef<str>>(&self, colocated: &[S]) -> Placement {
        let mut p = self.clone();
        for h in p.agent_hosts.iter_mut() {
            if colocated.iter().any(|c| c.as_ref() == h.as_str()) {
                *h = self.launcher.clone();
            }
        }
        p
    }

    fn hosts_of(&self, parties: &[Party], scope: Scope, i: Option<usize>) -> BTreeSet<&str> {
        let mut s = BTreeSet::new();
        for p in parties {
            match p {
                Party::Orchestrator | Party::Plant | Party::Leader | Party::Clients => {
                    s.insert(self.launcher.as_str());
                }
                Party::Agent => match (scope, i) {
                    (Scope::PerAgent, Some(i)) => {
                        if let Some(h) = self.agent_hosts.get(i) {
                            s.insert(h.as_str());
                        }
                    }
                    _ => s.extend(self.agent_hosts.iter().map(String::as_str)),
                },
                Party::Neighbours => {
                    if let Some(ns) = i.and_then(|i| self.neighbours.get(i)) {
                        s.extend(
                            ns.iter()
                                .filter_map(|&j| self.agent_hosts.get(j))
                                .map(String::as_str),
                        );
                    }
                }
            }
        }
        s
    }

    /// What `me`'s bridge does with a service whose senders and receivers are these parties.
    /// `Err` if `me` would both forward it and receive it (a loop).
    pub fn route(
        &self,
        me: &str,
        name: &str,
        senders: &[Party],
        receivers: &[Party],
        scope: Scope,
        i: Option<usize>,
    ) -> Result<Route, PlanError> {
        let from = self.hosts_of(senders, scope, i);
        let to = self.hosts_of(receivers, scope, i);
        let mut r = Route::default();
        if from.contains(me) {
            r.out_to = to
                .iter()
                .filter(|h| **h != me)
                .map(|h| h.to_string())
                .collect();
        }
        r.inbound = to.contains(me) && from.iter().any(|h| *h != me);
        if r.inbound && !r.out_to.is_empty() {
            return Err(PlanError::BothWays {
                service: name.to_string(),
                host: me.to_string(),
                from: format!("{from:?}"),
                to: format!("{to:?}"),
            });
        }
        Ok(r)
    }
}

/// Why a placement cannot be re-planned or routed: the host or service and what failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlanError {
    /// The launcher was lost: the run ends with it.
    #[error("host {0} is the launcher: the run cannot survive its loss")]
    LauncherLost(String),
    /// A lost host with no agent of the run (already handled).
    #[error("no agent of the run is placed on {0}")]
    NoAgentOn(String),
    /// A service a host would both forward and receive.
    #[error("service {service}: host {host} would both forward and receive it (senders on {from}, receivers on {to})")]
    BothWays {
        /// The service.
        service: String,
        /// The host.
        host: String,
        /// The senders' hosts.
        from: String,
        /// The receivers' hosts.
        to: String,
    },
}

crate::error::into_string!(PlanError);

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::protocol::services::{
        self, Event, Limits, Message, Named, Sizing, Slice, Topic, Visitor,
    };

    /// (name, senders, receivers, scope, index) of one service.
    type Service = (
        String,
        &'static [Party],
        &'static [Party],
        Scope,
        Option<usize>,
    );

    /// Every service of the table.
    #[derive(Default)]
    struct All(Vec<Service>);

    impl Visitor for All {
        type Error = ();
        fn topic<T: Message>(&mut self, s: Named<Topic<T>>, _: Limits) -> Result<(), ()> {
            let i = agent_index(s.spec.pattern, &s.name);
            self.0.push((
                s.name,
                s.spec.publishers,
                s.spec.subscribers,
                s.spec.scope,
                i,
            ));
            Ok(())
        }
        fn slices<T: Message>(&mut self, s: Named<Topic<T, Slice>>, _: Limits) -> Result<(), ()> {
            let i = agent_index(s.spec.pattern, &s.name);
            self.0.push((
                s.name,
                s.spec.publishers,
                s.spec.subscribers,
                s.spec.scope,
                i,
            ));
            Ok(())
        }
        fn event(&mut self, s: Named<Event>, _: Limits) -> Result<(), ()> {
            let i = agent_index(s.spec.pattern, &s.name);
            self.0
                .push((s.name, s.spec.notifiers, s.spec.listeners, s.spec.scope, i));
            Ok(())
        }
    }

    fn paper_neighbours() -> Vec<Vec<usize>> {
        Placement::neighbours_of(5, [(1, 2), (2, 3), (3, 4), (4, 5)])
    }

    #[test]
    fn the_agent_index_is_read_from_a_per_agent_name() {
        assert_eq!(
            agent_index("formation/agent/{i}/state", "formation/agent/12/state"),
            Some(12)
        );
        assert_eq!(
            agent_index("formation/wake/agent/{i}", "formation/wake/agent/0"),
            Some(0)
        );
        assert_eq!(
            agent_index("formation/reference", "formation/reference"),
            None
        );
    }

    #[test]
    fn no_placement_of_five_agents_over_three_hosts_makes_a_bridge_loop() {
        let mut all = All::default();
        services::visit(&Sizing::run(5, false), &mut all).unwrap();
        let names = ["a", "b", "c"];
        for code in 0..3usize.pow(5) {
            let agent_hosts: Vec<String> = (0..5)
                .map(|i| names[(code / 3usize.pow(i as u32)) % 3].to_string())
                .collect();
            let p = Placement {
                agent_hosts,
                launcher: "a".into(),
                neighbours: paper_neighbours(),
            };
            for (name, s, r, scope, i) in &all.0 {
                for me in names {
                    p.route(me, name, s, r, *scope, *i).unwrap();
                }
            }
        }
    }

    #[test]
    fn a_twenty_ring_round_robin_over_three_hosts_routes_shares_between_the_daemons_without_a_loop()
    {
        let n = 20;
        let names = ["a", "b", "c"];
        let p = Placement {
            agent_hosts: (0..n).map(|i| names[i % 3].to_string()).collect(),
            launcher: "a".into(),
            neighbours: Placement::neighbours_of(n, (1..=n).map(|i| (i, i % n + 1))),
        };
        let mut all = All::default();
        services::visit(&Sizing::run(n, false), &mut all).unwrap();
        for (name, s, r, scope, i) in &all.0 {
            for me in names {
                p.route(me, name, s, r, *scope, *i).unwrap();
            }
        }
        let route = |me: &str, name: &str| {
            let (n, s, r, scope, i) = all.0.iter().find(|x| x.0 == name).unwrap();
            p.route(me, n, s, r, *scope, *i).unwrap()
        };
        // Agent 2 (b) shares with agents 1 (a) and 3 (c), and wakes agent 3 on c.
        assert_eq!(route("b", "formation/agent/1/share").out_to, ["a", "c"]);
        assert!(route("c", "formation/agent/1/share").inbound);
        assert!(route("a", "formation/agent/1/share").inbound);
        assert_eq!(route("b", "formation/wake/agent/2").out_to, ["c"]);
        assert!(route("c", "formation/wake/agent/2").inbound);
        // Agent 20 (b) closes the ring between agents 19 and 1, both on a.
        assert_eq!(route("b", "formation/agent/19/share").out_to, ["a"]);
        // The plant's state of agent 3 goes a -> c only; its command c -> a only.
        assert_eq!(route("a", "formation/agent/2/state").out_to, ["c"]);
        assert!(route("b", "formation/agent/2/state").is_idle());
        assert_eq!(route("c", "formation/agent/2/command").out_to, ["a"]);
    }

    #[test]
    fn a_lost_hosts_agents_move_to_the_launcher_and_nothing_else_moves() {
        let p = Placement {
            agent_hosts: ["a", "b", "c", "b", "c"].map(String::from).to_vec(),
            launcher: "a".into(),
            neighbours: paper_neighbours(),
        };
        let (next, moved) = p.after_loss("b").unwrap();
        assert_eq!(moved, vec![1, 3]);
        assert_eq!(next.agent_hosts, ["a", "a", "c", "a", "c"]);
        assert_eq!(next.hosts(), ["a", "c"], "b is gone from the run");
        assert_eq!(next.launcher, "a");
        assert!(p
            .after_loss("a")
            .unwrap_err()
            .to_string()
            .contains("launcher"));
        assert!(
            next.after_loss("b").is_err(),
            "a host already handled moves nothing"
        );
    }

    #[test]
    fn after_a_loss_no_bridge_sends_to_or_expects_the_lost_host_and_none_loops() {
        let mut all = All::default();
        services::visit(&Sizing::run(5, false), &mut all).unwrap();
        let names = ["a", "b", "c"];
        // Every placement of the five agents over three hosts, each host but the launcher lost.
        for code in 0..3usize.pow(5) {
            let agent_hosts: Vec<String> = (0..5)
                .map(|i| names[(code / 3usize.pow(i as u32)) % 3].to_string())
                .collect();
            let p = Placement {
                agent_hosts,
                launcher: "a".into(),
                neighbours: paper_neighbours(),
            };
            for lost in ["b", "c"] {
                let Ok((next, moved)) = p.after_loss(lost) else {
                    assert!(p.agents_on(lost).is_empty());
                    continue;
                };
                for (name, s, r, scope, i) in &all.0 {
                    for me in next.hosts() {
                        let route = next.route(&me, name, s, r, *scope, *i).unwrap();
                        assert!(
                            !route.out_to.iter().any(|h| h == lost),
                            "{me} still sends {name} to the lost {lost}"
                        );
                    }
                    // A moved agent's own services stay on the launcher now.
                    let own = i.is_some_and(|k| moved.contains(&k))
                        && *scope == Scope::PerAgent
                        && !s.iter().chain(r.iter()).any(|x| *x == Party::Neighbours);
                    if own {
                        for me in next.hosts().iter().filter(|h| *h != "a") {
                            let route = next.route(me, name, s, r, *scope, *i).unwrap();
                            assert!(route.is_idle(), "{me} forwards {name} of a moved agent");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn re_planning_a_split_after_its_host_is_lost_leaves_the_launcher_bridge_idle() {
        let p = Placement {
            agent_hosts: ["a", "a", "a", "b", "b"].map(String::from).to_vec(),
            launcher: "a".into(),
            neighbours: paper_neighbours(),
        };
        let (next, moved) = p.after_loss("b").unwrap();
        assert_eq!(moved, vec![3, 4]);
        let mut all = All::default();
        services::visit(&Sizing::run(5, false), &mut all).unwrap();
        for (name, s, r, scope, i) in &all.0 {
            assert!(
                next.route("a", name, s, r, *scope, *i).unwrap().is_idle(),
                "{name} still crosses"
            );
        }
    }

    #[test]
    fn a_co_located_hosts_agents_are_the_launchers_for_every_bridge() {
        // Agents 4 and 5 on b, which shares the launcher's /dev/shm; agent 2 on c, remote.
        let p = Placement {
            agent_hosts: ["a", "c", "a", "b", "b"].map(String::from).to_vec(),
            launcher: "a".into(),
            neighbours: paper_neighbours(),
        };
        let d = p.data_plane(&["b"]);
        assert_eq!(d.agent_hosts, ["a", "c", "a", "a", "a"]);
        assert_eq!(d.hosts(), ["a", "c"], "no bridge plans for b");
        assert_eq!(
            p.data_plane::<&str>(&[]),
            p,
            "nothing co-located: unchanged"
        );
        let mut all = All::default();
        services::visit(&Sizing::run(5, false), &mut all).unwrap();
        for (name, s, r, scope, i) in &all.0 {
            for me in ["a", "c"] {
                let route = d.route(me, name, s, r, *scope, *i).unwrap();
                assert!(
                    !route.out_to.iter().any(|h| h == "b"),
                    "{me} sends {name} to the co-located b"
                );
            }
            // What only concerns agents 4 and 5 stays on the launcher.
            if i.is_some_and(|k| k >= 3)
                && !s.iter().chain(r.iter()).any(|x| *x == Party::Neighbours)
            {
                assert!(
                    d.route("a", name, s, r, *scope, *i).unwrap().is_idle(),
                    "{name}"
                );
            }
        }
        // All co-located: the launcher's bridge has nothing to do.
        let only_b = Placement {
            agent_hosts: ["a", "a", "a", "b", "b"].map(String::from).to_vec(),
            ..p.clone()
        }
        .data_plane(&["b"]);
        for (name, s, r, scope, i) in &all.0 {
            assert!(
                only_b.route("a", name, s, r, *scope, *i).unwrap().is_idle(),
                "{name} crosses"
            );
        }
        // A co-located host lost: its agents go to the launcher, where the data plane had them.
        let (next, moved) = p.after_loss("b").unwrap();
        assert_eq!(moved, vec![3, 4]);
        assert_eq!(next.data_plane(&["b"]), d);
    }

    #[test]
    fn a_split_forwards_exactly_what_crosses_and_nothing_of_the_launcher_alone() {
        // Agents 4 and 5 on b (the paper path 1-2-3-4-5).
        let p = Placement {
            agent_hosts: ["a", "a", "a", "b", "b"].map(String::from).to_vec(),
            launcher: "a".into(),
            neighbours: paper_neighbours(),
        };
        let mut all = All::default();
        services::visit(&Sizing::run(5, false), &mut all).unwrap();
        let route = |me: &str, name: &str| {
            let (n, s, r, scope, i) = all.0.iter().find(|x| x.0 == name).unwrap();
            p.route(me, n, s, r, *scope, *i).unwrap()
        };
        // The plant's state of agent 4 goes a -> b; agent 1's stays on a.
        assert_eq!(route("a", "formation/agent/3/state").out_to, vec!["b"]);
        assert!(route("b", "formation/agent/3/state").inbound);
        assert!(route("a", "formation/agent/0/state").is_idle());
        assert!(route("b", "formation/agent/0/state").is_idle());
        // Agent 3 (a) shares with 2 (a) and 4 (b); agent 5 (b) only with 4 (b).
        assert_eq!(route("a", "formation/agent/2/share").out_to, vec!["b"]);
        assert!(route("a", "formation/agent/4/share").is_idle());
        assert!(route("b", "formation/agent/4/share").is_idle());
        // Commands, hellos and the plant's wake-ups come back b -> a.
        assert_eq!(route("b", "formation/agent/4/command").out_to, vec!["a"]);
        assert_eq!(route("b", "formation/run/hello").out_to, vec!["a"]);
        assert_eq!(route("b", "formation/wake/plant").out_to, vec!["a"]);
        assert!(route("a", "formation/wake/plant").inbound);
        // The step records never leave the launcher.
        assert!(route("a", "formation/plant/steps").is_idle());
        assert!(route("b", "formation/plant/steps").is_idle());
        // Run-wide inputs of the agents go out once to b.
        assert_eq!(route("a", "formation/run/control").out_to, vec!["b"]);
        assert_eq!(route("a", "formation/reference").out_to, vec!["b"]);
    }
}
