//! Deterministic simulations of several agents on the in-process bus behind the seeded fault injector: loss,
//! duplication, reordering, a healed partition and a restart, over many seeds. Every replica converges (equal
//! digests and contexts) and the replica invariants hold after every step. Also: late join, change signals,
//! bad samples, id collisions, two graphs on one bus.

use std::sync::Arc;
use std::time::Duration;

use agent::envelope::Message;
use agent::{Agent, AgentConfig, AgentId, ChangeSignal, GraphId};
use bytes::Bytes;
use dsr::{Change, NewNode, NodeId, Replica, ReplicaId, Value, attrs};
use transport::fault::{FaultConfig, FaultInjector, FaultPlan};
use transport::inproc::{Bus, InProcTransport};
use transport::rng::SplitMix64;
use transport::{Channel, Clock, ManualClock, Transport};

type SimAgent = Agent<FaultInjector<InProcTransport>>;

const STEP_NS: u64 = 1_000_000;

struct Sim {
    bus: Bus,
    clock: ManualClock,
    plan: FaultPlan,
    agents: Vec<SimAgent>,
    rng: SplitMix64,
    next_nonce: u64,
}

fn config(id: u32, nonce: u64) -> AgentConfig {
    AgentConfig {
        join_wait: Duration::from_millis(300),
        join_retry: Duration::from_millis(20),
        // Below the join wait less a retry, as the defaults are: a lost graph answer is sent again in time.
        answer_hold: Duration::from_millis(100),
        announce_period: Duration::from_millis(40),
        nonce: Some(nonce),
        // One graph, named: agents that start alone at once (a partition at start) are still of one graph.
        graph: GraphId::new(0x51),
        ..AgentConfig::new(AgentId(id))
    }
}

impl Sim {
    fn new(seed: u64, faults: FaultConfig) -> Self {
        Sim {
            bus: Bus::new(),
            clock: ManualClock::new(1_000_000_000),
            plan: FaultPlan::new(seed, faults),
            agents: Vec::new(),
            rng: SplitMix64::new(seed ^ 0xABCD),
            next_nonce: seed.wrapping_mul(31) | 1,
        }
    }

    fn spawn(&mut self, id: u32) -> usize {
        self.spawn_with(id, |config| config)
    }

    /// Spawns agent `id` with the simulation's configuration changed by `adjust`.
    fn spawn_with(&mut self, id: u32, adjust: impl FnOnce(AgentConfig) -> AgentConfig) -> usize {
        self.next_nonce += 1;
        let transport = self.plan.wrap(self.bus.attach(100_000), Arc::new(self.clock.clone()) as Arc<dyn Clock>);
        let config = adjust(config(id, self.next_nonce));
        let agent = Agent::new(config, transport, Arc::new(self.clock.clone())).unwrap();
        self.agents.push(agent);
        self.agents.len() - 1
    }

    fn step(&mut self) {
        self.clock.advance(STEP_NS);
        for agent in &self.agents {
            agent.pump();
        }
        for agent in &self.agents {
            if let Some(Err(error)) = agent.read(Replica::check_invariants) {
                panic!("{}: invariant broken: {error}", agent.id());
            }
        }
    }

    fn steps(&mut self, n: usize) {
        for _ in 0..n {
            self.step();
        }
    }

    /// One random operation by a random ready agent.
    fn random_write(&mut self) {
        let index = self.rng.range(0, self.agents.len() as u64 - 1) as usize;
        let agent = &self.agents[index];
        let Some(nodes) = agent.read(|r| r.nodes().map(|n| n.id()).collect::<Vec<NodeId>>()) else { return };
        let pick = |rng: &mut SplitMix64| nodes[rng.range(0, nodes.len() as u64 - 1) as usize];
        let roll = self.rng.range(0, 99);
        let outcome = if nodes.is_empty() || roll < 25 {
            let name = format!("n{}", self.rng.next_u64() % 1_000_000);
            agent.insert_node(NewNode::new("object", &name).with_attr("pos_x", 1.0f32)).map(|_| ())
        } else if roll < 70 {
            let id = pick(&mut self.rng);
            agent.set_attr(id, attrs::POS_X, self.rng.next_f64() as f32)
        } else if roll < 85 {
            let (from, to) = (pick(&mut self.rng), pick(&mut self.rng));
            agent.insert_edge(from, to, "in", vec![]).map(|_| ())
        } else if roll < 92 {
            let key = agent.read(|r| r.edges().next().map(|e| e.key().clone())).flatten();
            match key {
                Some(key) => agent.delete_edge(&key),
                None => Ok(()),
            }
        } else {
            agent.delete_node(pick(&mut self.rng))
        };
        // Refusals (a self-loop edge that exists, a node deleted meanwhile, ...) are normal in a random workload.
        let _ = outcome;
    }

    fn converged(&self) -> bool {
        let digests: Vec<_> = self.agents.iter().map(|a| a.digest()).collect();
        let contexts: Vec<_> = self.agents.iter().map(|a| a.read(|r| r.context().clone())).collect();
        digests.iter().all(|d| d.is_some() && *d == digests[0]) && contexts.iter().all(|c| *c == contexts[0])
    }

    /// Steps until every replica is equal; panics after a bounded number of steps.
    fn settle(&mut self, limit: usize) -> usize {
        for n in 0..limit {
            if self.converged() {
                return n;
            }
            self.step();
        }
        let summary: Vec<String> = self
            .agents
            .iter()
            .map(|a| {
                let ctx = a.read(|r| r.context().clone()).unwrap();
                format!("{} {:?} {:?} cloud {:?}", a.id(), a.digest().unwrap(), ctx.version_vector(), ctx.cloud())
            })
            .collect();
        let graphs: Vec<_> = self.agents.iter().map(|a| a.visible_graph().unwrap()).collect();
        for (id, node) in &graphs[0].nodes {
            if graphs[1].nodes.get(id) != Some(node) {
                eprintln!("node {id}: {node:?} vs {:?}", graphs[1].nodes.get(id));
            }
        }
        for id in graphs[1].nodes.keys() {
            if !graphs[0].nodes.contains_key(id) {
                eprintln!("node {id} only in the second");
            }
        }
        for (key, edge) in &graphs[0].edges {
            if graphs[1].edges.get(key) != Some(edge) {
                eprintln!("edge {key}: {edge:?} vs {:?}", graphs[1].edges.get(key));
            }
        }
        panic!("no convergence after {limit} steps: {summary:?}");
    }
}

fn faults() -> FaultConfig {
    FaultConfig {
        loss: 0.10,
        duplicate: 0.05,
        reorder: 0.2,
        reorder_ns: 8 * STEP_NS,
        delay_ns: (0, 2 * STEP_NS),
        ..FaultConfig::default()
    }
}

fn scenario(seed: u64) {
    let mut sim = Sim::new(seed, faults());
    let first = sim.spawn(1);
    sim.steps(400); // alone after the join wait
    assert!(sim.agents[first].is_ready());
    sim.spawn(2);
    sim.spawn(3);
    sim.steps(200);
    assert!(sim.agents.iter().all(Agent::is_ready), "seed {seed}: late joiners got the graph");

    for _ in 0..300 {
        sim.random_write();
        sim.step();
    }

    // A partition: agent 3 alone on one side, writes on both sides, then heal.
    let ids: Vec<_> = sim.agents.iter().map(|a| a.transport().local_id()).collect();
    sim.plan.partition(&ids[2..3], &ids[..2]);
    for _ in 0..200 {
        sim.random_write();
        sim.step();
    }
    sim.plan.heal();

    // A restart: agent 2's process dies and comes back with the same agent id.
    let old = sim.agents.remove(1);
    let old_replica = old.status().replica.unwrap();
    drop(old);
    let restarted = sim.spawn(2);
    sim.steps(100);
    let new_replica = sim.agents[restarted].status().replica.expect("restarted agent joined");
    assert_ne!(new_replica, old_replica, "seed {seed}: a new life never reuses a replica id");
    assert!(AgentId::incarnation_of(new_replica) > AgentId::incarnation_of(old_replica));
    for _ in 0..200 {
        sim.random_write();
        sim.step();
    }

    // Quiet: loss etc. still on; anti-entropy must bring everyone together.
    sim.settle(20_000);
    for agent in &sim.agents {
        let status = agent.status();
        assert_eq!(status.rejected, 0, "seed {seed}: {status:?}");
        // Anti-entropy by applied operations must converge on its own: the digest safety net never fires.
        assert_eq!(status.digest_mismatches, 0, "seed {seed}: {status:?}");
        assert!(status.collision.is_none(), "seed {seed}: {status:?}");
    }
}

#[test]
fn converges_under_loss_duplication_reordering_partition_and_restart_many_seeds() {
    for seed in 0..12 {
        scenario(seed);
    }
}

/// Twelve agents in groups of four: each announces every third period. A partition with writes on both sides
/// heals with no write after it, so only periodic announces can start the repair.
fn large_group_scenario(seed: u64) {
    let mut sim = Sim::new(seed, faults());
    let group = |config: AgentConfig| AgentConfig { announce_group: 4, ..config };
    sim.spawn_with(1, group);
    sim.steps(400);
    for id in 2..=12 {
        sim.spawn_with(id, group);
    }
    sim.steps(400);
    assert!(sim.agents.iter().all(Agent::is_ready), "seed {seed}: every joiner got the graph");
    for _ in 0..200 {
        sim.random_write();
        sim.step();
    }
    let ids: Vec<_> = sim.agents.iter().map(|a| a.transport().local_id()).collect();
    sim.plan.partition(&ids[..5], &ids[5..]);
    for _ in 0..200 {
        sim.random_write();
        sim.step();
    }
    sim.plan.heal();
    sim.settle(20_000);
    for agent in &sim.agents {
        assert_eq!(agent.status().digest_mismatches, 0, "seed {seed}");
    }
}

#[test]
fn a_group_larger_than_its_announce_group_converges_after_a_partition_healed_without_writes() {
    for seed in 0..3 {
        large_group_scenario(seed);
    }
}

#[test]
fn late_joiner_gets_the_seed_graph_from_any_peer_and_signals_flow_with_origins() {
    let mut sim = Sim::new(99, FaultConfig::default());
    // Agent 1 starts alone from a seed graph.
    let mut seed = Replica::new(ReplicaId(4095));
    let (world, _) = seed.insert_node(1, NewNode::new("world", "world").with_id(NodeId(100))).unwrap();
    seed.insert_node(2, NewNode::new("omnirobot", "robot").with_id(NodeId(101)).with_attr("level", 1)).unwrap();
    seed.insert_edge(3, world, NodeId(101), "RT", vec![]).unwrap();
    let graph = dsr::json::CortexGraph::from_replica(&seed);
    sim.next_nonce += 1;
    let transport = sim.plan.wrap(sim.bus.attach(1000), Arc::new(sim.clock.clone()) as Arc<dyn Clock>);
    let mut cfg = config(1, sim.next_nonce);
    cfg.seed = Some(graph);
    sim.agents.push(Agent::new(cfg, transport, Arc::new(sim.clock.clone())).unwrap());
    sim.steps(400);
    assert_eq!(sim.agents[0].status().nodes, 2);

    // Agent 2 joins from agent 1; agent 1 then leaves; agent 3 joins from agent 2 (no special server).
    sim.spawn(2);
    sim.steps(50);
    assert_eq!(sim.agents[1].node(NodeId(101)).unwrap().name, "robot");
    sim.agents.remove(0);
    sim.spawn(3);
    sim.steps(50);
    assert_eq!(sim.agents[1].status().nodes, 2, "agent 3 got the graph from agent 2");
    let waited = sim.agents[1].status();
    assert!(waited.ready && waited.replica.is_some());

    // Change signals, remote and local, with the originating agent.
    let remote = sim.agents[1].subscribe(64);
    let local = sim.agents[0].subscribe(64);
    let id = sim.agents[0].insert_node(NewNode::new("person", "alice")).unwrap();
    sim.agents[0].set_attr(id, attrs::POS_Y, 2.5f32).unwrap();
    sim.steps(5);
    let seen: Vec<ChangeSignal> = remote.try_iter().collect();
    assert!(seen.iter().any(|s| s.change == Change::NodeInserted { id } && s.origin == Some(AgentId(2)) && !s.local));
    assert!(seen.last().is_some_and(|s| s.last_together), "the last change of a delta closes it: {seen:?}");
    assert!(seen.iter().any(|s| matches!(&s.change, Change::AttrUpdated { name, .. } if name.as_str() == "pos_y")));
    let mine: Vec<ChangeSignal> = local.try_iter().collect();
    assert!(mine.iter().all(|s| s.local && s.origin == Some(AgentId(2))) && mine.len() >= 2, "{mine:?}");
    assert_eq!(sim.agents[1].attr(id, attrs::POS_Y), Some(2.5));
}

#[test]
fn malformed_and_foreign_samples_are_dropped_and_the_graph_stays_intact() {
    let mut sim = Sim::new(5, FaultConfig::default());
    sim.spawn(1);
    sim.steps(400);
    let a = &sim.agents[0];
    let id = a.insert_node(NewNode::new("object", "cup").with_attr("pos_x", 1.0f32)).unwrap();
    let before = a.digest();
    let rogue = sim.bus.attach(16);
    // A delta whose attribute has another type than the one the agent knows.
    let mut other = Replica::with_dictionary(ReplicaId(77), dsr::Dictionary::permissive());
    let (node, _) = other.insert_node(1, NewNode::new("object", "x").with_id(NodeId(5))).unwrap();
    let wrong = other.set_attrs(2, node, [("speed", Value::I32(3))]).unwrap();
    let good_delta = Message::Delta { from: AgentId(9), delta: Bytes::from(wrong.encode()) }.encode(GraphId::new(0x51));
    let mut bad_delta = good_delta.to_vec();
    let last = bad_delta.len() - 1;
    bad_delta[last] ^= 0xFF;
    let samples: Vec<Bytes> = vec![
        Bytes::from_static(b"RTPS garbage"),
        Bytes::from_static(&[0xD5, 9, 1, 0]),
        Bytes::from_static(&[0xD5, 2, 77]),
        Bytes::from_static(&[0xD5, 2, 77, 0x51, 0, 0, 0, 0, 0, 0, 0]),
        Bytes::from(bad_delta),
        Bytes::from(vec![0xD5, 2, 2, 0x51, 0, 0, 0, 0, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]),
        Bytes::from(vec![0xD5, 2, 1, 0x51, 0, 0, 0, 0, 0, 0, 0, 3]),
        Bytes::from(vec![0xD5, 2, 1, 0, 0, 0, 0, 0, 0, 0, 0, 3]),
    ];
    let count = samples.len();
    for bytes in samples {
        rogue.publish(Channel::Updates, bytes).unwrap();
    }
    rogue.publish(Channel::Updates, good_delta).unwrap();
    sim.steps(3);
    let a = &sim.agents[0];
    let status = a.status();
    assert!(status.rejected as usize >= count, "{status:?}");
    assert_eq!(a.node(id).unwrap().attrs.get("pos_x"), Some(&Value::F32(1.0)));
    assert!(a.node(NodeId(5)).is_none(), "the wrongly typed delta was refused whole");
    assert_eq!(a.digest(), before);
    a.set_attr(id, attrs::POS_X, 3.0f32).unwrap();
}

#[test]
fn two_live_agents_with_one_id_detect_the_collision_and_refuse_writes() {
    let mut sim = Sim::new(11, FaultConfig::default());
    sim.spawn(7);
    sim.steps(400);
    sim.spawn(7);
    sim.steps(100);
    for agent in &sim.agents {
        let status = agent.status();
        assert!(status.collision.is_some(), "{status:?}");
    }
    let error = sim.agents[0].insert_node(NewNode::new("object", "z")).unwrap_err();
    assert!(error.to_string().contains("collision"), "{error}");
}

#[test]
fn each_remote_update_gives_exactly_one_signal() {
    let mut sim = Sim::new(7, FaultConfig::default());
    sim.spawn(1);
    sim.steps(400);
    sim.spawn(2);
    sim.steps(50);
    let id = sim.agents[0].insert_node(NewNode::new("object", "ping")).unwrap();
    sim.steps(5);
    let remote = sim.agents[1].subscribe(1024);
    for i in 0..20 {
        sim.agents[0].set_attr(id, attrs::POS_X, i as f32).unwrap();
        sim.steps(3);
    }
    let updates = remote
        .try_iter()
        .filter(|s| matches!(&s.change, Change::AttrUpdated { name, .. } if name.as_str() == "pos_x"))
        .count();
    assert_eq!(updates, 20);
}

#[test]
fn a_delta_that_shows_a_gap_gets_the_missing_one_at_once_not_at_the_next_announce() {
    let mut sim = Sim::new(11, FaultConfig::default());
    for id in [1, 2] {
        // Announces far apart: only a gap request can repair within the test's few steps.
        sim.spawn_with(id, |config| AgentConfig { announce_period: Duration::from_secs(3600), ..config });
        sim.steps(400);
    }
    let id = sim.agents[0].insert_node(NewNode::new("object", "cup")).unwrap();
    sim.steps(5);
    assert!(sim.converged());

    // Everything received is lost while agent 1 makes one update; then the network is perfect again.
    sim.plan.set_config(FaultConfig { loss: 1.0, ..FaultConfig::default() });
    sim.agents[0].set_attr(id, attrs::POS_X, 1.0f32).unwrap();
    sim.steps(2);
    sim.plan.set_config(FaultConfig::default());
    assert_eq!(sim.agents[1].attr(id, attrs::POS_X), None);
    assert_eq!(sim.agents[1].status().gap_requests, 0);

    // The next update shows the gap: agent 2 asks agent 1 at once and has both within a few steps.
    sim.agents[0].set_attr(id, attrs::POS_Y, 2.0f32).unwrap();
    let steps = sim.settle(10);
    assert!(steps <= 5, "converged after {steps} steps");
    assert_eq!(sim.agents[1].attr(id, attrs::POS_X), Some(1.0));
    assert_eq!(sim.agents[1].status().gap_requests, 1);
    assert_eq!(sim.agents[0].status().gap_requests, 0);
}

#[test]
fn a_lost_last_write_is_announced_once_the_writer_is_quiet_not_at_the_next_period() {
    let mut sim = Sim::new(13, FaultConfig::default());
    for id in [1, 2] {
        // Periodic announces far apart: only the announce after the writer falls quiet can repair in time.
        sim.spawn_with(id, |config| AgentConfig {
            announce_period: Duration::from_secs(3600),
            quiet_announce: Duration::from_millis(30),
            ..config
        });
        sim.steps(400);
    }
    let id = sim.agents[0].insert_node(NewNode::new("object", "cup")).unwrap();
    sim.steps(5);
    assert!(sim.converged());

    // Agent 1's last write is lost, and no later delta of it shows the gap.
    sim.plan.set_config(FaultConfig { loss: 1.0, ..FaultConfig::default() });
    sim.agents[0].set_attr(id, attrs::POS_X, 1.0f32).unwrap();
    sim.steps(2);
    sim.plan.set_config(FaultConfig::default());
    sim.steps(20);
    assert_eq!(sim.agents[1].attr(id, attrs::POS_X), None, "nothing repairs it before the writer is quiet");
    // 30 ms (30 steps) after the write, agent 1 announces; agent 2 asks and gets the write.
    let steps = sim.settle(40);
    assert!(steps <= 15, "converged after {steps} more steps");
    assert_eq!(sim.agents[1].attr(id, attrs::POS_X), Some(1.0));
}

/// Two graphs on one bus (one domain and topic prefix): agents 1 and 2 of graph A, agent 3 of graph B, all writing
/// under loss and reordering. A's agents converge without a trace of B's writes, B keeps its own, and each agent
/// reports the other graph once and counts every refused message.
#[test]
fn two_graphs_on_one_bus_never_merge_and_each_refuses_the_other() {
    let (graph_a, graph_b) = (GraphId::new(0xa).unwrap(), GraphId::new(0xb).unwrap());
    let mut sim = Sim::new(23, FaultConfig { loss: 0.05, reorder: 0.1, ..FaultConfig::default() });
    sim.spawn_with(1, |c| AgentConfig { graph: Some(graph_a), ..c });
    sim.spawn_with(2, |c| AgentConfig { graph: None, join_wait: Duration::from_secs(60), ..c });
    sim.spawn_with(3, |c| AgentConfig { graph: Some(graph_b), ..c });
    sim.steps(400);
    assert!(sim.agents[0].is_ready() && sim.agents[2].is_ready());
    // Agent 2 named no graph: it asked everyone and took the first answer (from 1 or 3); the checks follow it.
    let joined = sim.agents[1].status().graph;
    assert!(joined == Some(graph_a) || joined == Some(graph_b), "{joined:?}");
    for round in 0..200u32 {
        for (index, agent) in sim.agents.iter().enumerate() {
            let _ = agent.insert_node(NewNode::new("object", &format!("n{index}_{round}")));
        }
        sim.step();
    }
    let mut steps = 0;
    while steps < 20_000 {
        let same = |i: usize, j: usize| sim.agents[i].digest() == sim.agents[j].digest();
        let done = if joined == Some(graph_a) { same(0, 1) } else { same(1, 2) };
        if done {
            break;
        }
        sim.step();
        steps += 1;
    }
    let names = |index: usize| -> Vec<String> {
        sim.agents[index].read(|r| r.nodes().map(|n| n.name().into_owned()).collect()).unwrap()
    };
    let (partner, stranger) = if joined == Some(graph_a) { (0, 2) } else { (2, 0) };
    assert_eq!(sim.agents[1].digest(), sim.agents[partner].digest(), "agent 2 converged with its graph");
    let writes_of = |index: usize| format!("n{index}_");
    for index in [1, partner] {
        let held = names(index);
        assert!(!held.iter().any(|n| n.starts_with(&writes_of(stranger))), "agent {index} holds a foreign write");
        assert!(
            held.iter().any(|n| n.starts_with(&writes_of(1)))
                && held.iter().any(|n| n.starts_with(&writes_of(partner)))
        );
    }
    assert!(!names(stranger).iter().any(|n| n.starts_with("n1_") || n.starts_with(&writes_of(partner))));
    for agent in &sim.agents {
        let status = agent.status();
        assert_eq!(status.foreign_graphs.len(), 1, "one foreign graph heard: {status:?}");
        assert!(status.foreign_refused > 0);
        assert_ne!(status.foreign_graphs[0], status.graph.unwrap());
    }
}
