//! The protocol core alone (no transport, no threads): how a life chooses its replica id, and what happens when a
//! replica id is reused anyway.

use std::time::Duration;

use agent::core::{AgentCore, Event, Input, LifeSeed, Output};
use agent::envelope::{Envelope, Message};
use agent::{AgentConfig, AgentId, GraphId};
use dsr::NewNode;

/// The graph the tests' lives belong to, unless they say otherwise.
fn graph_g() -> Option<GraphId> {
    GraphId::new(0x6a)
}

/// A life of agent 3 of graph G that starts alone at its first tick.
fn alone(nonce: u64, recorded_incarnation: Option<u32>) -> (AgentCore, Output) {
    let config = AgentConfig { join_wait: Duration::ZERO, graph: graph_g(), ..AgentConfig::new(AgentId(3)) };
    let mut core =
        AgentCore::new(config.protocol(), LifeSeed { nonce, recorded_incarnation, ..LifeSeed::default() }, None, 0);
    let out = core.tick(0);
    assert!(core.is_ready());
    (core, out)
}

fn incarnation(out: &Output) -> u32 {
    out.events
        .iter()
        .find_map(|event| match event {
            Event::Ready { incarnation, .. } => Some(*incarnation),
            _ => None,
        })
        .expect("a Ready event")
}

/// Hands every message of `out` to `to`, as the network would.
fn deliver(out: &[agent::core::Send], to: &mut AgentCore) -> Vec<Event> {
    let mut events = Vec::new();
    for send in out {
        let envelope = Envelope::decode(&send.encode()).unwrap();
        if let Some(input) = Input::decode(envelope.message).input {
            events.extend(to.handle(1, envelope.graph, input).events);
        }
    }
    events
}

#[test]
fn a_life_takes_the_incarnation_above_its_record() {
    let (_, out) = alone(42, Some(7));
    assert_eq!(incarnation(&out), 8);
}

#[test]
fn without_a_record_the_floor_comes_from_the_nonce() {
    let (_, a) = alone(5, None);
    let (_, b) = alone(6, None);
    assert_eq!((incarnation(&a), incarnation(&b)), (6, 7));
}

#[test]
fn a_peer_holding_operations_of_this_lifes_replica_id_is_a_collision_and_writes_stop() {
    // Two record-less lives whose nonces give the same floor take the same replica id (the 2^-16 case).
    let (mut earlier, _) = alone(5, None);
    let (mut later, _) = alone(5 + (1 << 16), None);
    assert_eq!(earlier.replica().unwrap().id(), later.replica().unwrap().id());
    let (_, written) =
        earlier.write(1, |r, now| r.insert_node(now, NewNode::new("object", "a")).map(|(_, d)| ((), vec![d]))).unwrap();
    let events = deliver(&written.sends(), &mut later);
    assert!(events.iter().any(|e| matches!(e, Event::Collision { .. })), "{events:?}");
    assert!(later.collision().is_some());
    let refused = later.write(2, |r, now| r.insert_node(now, NewNode::new("object", "b")).map(|(_, d)| ((), vec![d])));
    assert!(matches!(refused, Err(agent::core::WriteRefusal::Collision(_))));
}

#[test]
fn operations_of_this_lifes_own_id_that_it_made_are_no_collision() {
    let (mut a, _) = alone(9, None);
    let (_, written) =
        a.write(1, |r, now| r.insert_node(now, NewNode::new("object", "a")).map(|(_, d)| ((), vec![d]))).unwrap();
    // Its own delta coming back (a duplicate) says nothing new.
    let events = deliver(&written.sends(), &mut a);
    assert!(a.collision().is_none(), "{events:?}");
}

/// The answer to a missing-request of a life that lacks `frames` overwritten camera frames of `frame_bytes` each.
fn answer_to_a_peer_missing_frames(frames: u32, frame_bytes: usize) -> Vec<Message> {
    let (mut writer, _) = alone(11, Some(0));
    let (camera, _) = writer
        .write(1, |r, now| r.insert_node(now, NewNode::new("camera", "cam")).map(|(id, d)| (id, vec![d])))
        .unwrap();
    for frame in 0..frames {
        let image = dsr::Value::Bytes(vec![frame as u8; frame_bytes].into());
        writer
            .write(2 + u64::from(frame), |r, now| r.set_attrs(now, camera, [("cam_rgb", image)]).map(|d| ((), vec![d])))
            .unwrap();
    }
    let request =
        Message::MissingRequest { from: AgentId(4), to: AgentId(3), applied: dsr::CausalContext::new(), full: false };
    let envelope = Envelope::decode(&request.encode(graph_g())).unwrap();
    let input = Input::decode(envelope.message).input.unwrap();
    writer.handle(100, envelope.graph, input).sends.into_iter().map(|s| s.message).collect()
}

#[test]
fn a_peer_missing_many_overwritten_frames_gets_the_current_one_and_one_missing_a_few_gets_the_deltas() {
    // Twelve 300 kB frames of one camera: the history holds the current one, the others folded into it, so the
    // answer is the insert and one frame (not 3.6 MB of frames, nor a snapshot).
    let answer = answer_to_a_peer_missing_frames(12, 300_000);
    let deltas: Vec<&bytes::Bytes> = answer
        .iter()
        .flat_map(|m| match m {
            Message::Deltas { deltas, .. } => deltas.iter(),
            other => panic!("{}", other.kind()),
        })
        .collect();
    assert_eq!(deltas.len(), 2);
    let bytes: usize = deltas.iter().map(|d| d.len()).sum();
    assert!((300_000..301_000).contains(&bytes), "{bytes} bytes");
    // Two small frames: the deltas themselves (below the threshold, no snapshot is even encoded).
    let answer = answer_to_a_peer_missing_frames(2, 1_000);
    assert!(
        answer.iter().all(|m| matches!(m, Message::Deltas { .. })),
        "{:?}",
        answer.iter().map(Message::kind).collect::<Vec<_>>()
    );
}

/// Hands every message of `sends` to `to`; returns what `to` sends in reply.
fn exchange(sends: &[agent::core::Send], to: &mut AgentCore, now_ns: u64) -> Output {
    let mut replies = Output::default();
    for send in sends {
        let envelope = Envelope::decode(&send.encode()).unwrap();
        if let Some(input) = Input::decode(envelope.message).input {
            let out = to.handle(now_ns, envelope.graph, input);
            replies.sends.extend(out.sends);
            replies.events.extend(out.events);
        }
    }
    replies
}

/// A real graph of an older era (a user's node types and attribute names, `battery_load` as f32 where the built-in
/// dictionary says i32) seeds one agent with warnings, reaches a joiner with the built-in dictionary whole (the
/// network is not refused for names), and the joiner may then write the names it learnt.
#[test]
fn a_graph_of_another_era_reaches_a_joiner_whose_dictionary_learns_its_names() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../datasets/cortex-graphs/shadow_beta.json");
    let reading = dsr::json::read(&std::fs::read(path).unwrap(), dsr::json::Strictness::Lenient).unwrap();
    let config = AgentConfig { join_wait: Duration::ZERO, ..AgentConfig::new(AgentId(3)) };
    let mut seeded = AgentCore::new(
        config.protocol(),
        LifeSeed { nonce: 5, recorded_incarnation: None, ..LifeSeed::default() },
        Some(reading.graph),
        0,
    );
    let out = seeded.tick(0);
    let warnings = out.events.iter().filter(|event| matches!(event, Event::SeedWarning { .. })).count();
    assert_eq!(warnings, 8, "{:?}", out.events);

    let config = AgentConfig { join_wait: Duration::from_secs(5), ..AgentConfig::new(AgentId(4)) };
    let mut joiner = AgentCore::new(
        config.protocol(),
        LifeSeed { nonce: 6, recorded_incarnation: None, ..LifeSeed::default() },
        None,
        0,
    );
    let request = joiner.tick(1);
    let answer = exchange(&request.sends, &mut seeded, 2);
    let joined = exchange(&answer.sends, &mut joiner, 3);
    assert!(joiner.is_ready(), "{:?}", joined.events);
    assert!(!joined.events.iter().any(|event| matches!(event, Event::Rejected { .. })), "{:?}", joined.events);
    let (mine, theirs) = (joiner.replica().unwrap(), seeded.replica().unwrap());
    assert_eq!(mine.digest(), theirs.digest());
    assert_eq!(mine.dictionary().learned_types("battery_load"), [dsr::ValueType::F32]);

    let battery = mine.nodes().find(|node| node.attr("battery_load").is_some()).unwrap().id();
    joiner
        .write(4, |r, now| {
            let delta = r.set_attrs(now, battery, [("battery_load", dsr::Value::F32(0.5))])?;
            r.set_attrs(now, battery, [("servo_pos", dsr::Value::F32(1.0))]).map(|other| ((), vec![delta, other]))
        })
        .unwrap();
}

/// A life of agent `id` with announce period 100 ms and group `group`, alone and ready at time 0.
fn announcer(id: u32, group: u32) -> AgentCore {
    let config = AgentConfig {
        join_wait: Duration::ZERO,
        announce_period: Duration::from_millis(100),
        announce_group: group,
        graph: graph_g(),
        ..AgentConfig::new(AgentId(id))
    };
    let mut core = AgentCore::new(
        config.protocol(),
        LifeSeed { nonce: u64::from(id), recorded_incarnation: None, ..LifeSeed::default() },
        None,
        0,
    );
    core.tick(0);
    core
}

/// Times of the periodic announces `core` sends from `from_ns` to `until_ns`, ticking at every deadline.
fn announce_times(core: &mut AgentCore, from_ns: u64, until_ns: u64) -> Vec<u64> {
    let mut times = Vec::new();
    let mut now = from_ns;
    while now <= until_ns {
        let out = core.tick(now);
        if out.sends.iter().any(|send| matches!(send.message, Message::Announce { .. })) {
            times.push(now);
        }
        now = core.next_deadline_ns().max(now + 1);
    }
    times
}

/// Delivers to `to` at `now_ns` an announce of each of `peers` (group `group`).
fn announces_of(peers: std::ops::RangeInclusive<u32>, group: u32, now_ns: u64, to: &mut AgentCore) {
    for peer in peers {
        for send in announcer(peer, group).tick(1).sends {
            let envelope = Envelope::decode(&send.encode()).unwrap();
            if let Some(input) = Input::decode(envelope.message).input {
                to.handle(now_ns, envelope.graph, input);
            }
        }
    }
}

#[test]
fn an_agent_that_hears_more_agents_than_its_group_announces_less_often_in_proportion() {
    let mut core = announcer(1, 4);
    assert_eq!(core.announce_interval_ns(), 100_000_000, "alone: the announce period");
    // Eleven peers are heard (their announces): twelve agents, three groups of four.
    announces_of(2..=12, 4, 1, &mut core);
    assert_eq!(core.peers().len(), 11);
    assert_eq!(core.announce_interval_ns(), 300_000_000);
    // The peers go on announcing, once an interval each.
    let mut times = Vec::new();
    let mut now = 1_000_000_000;
    while now <= 2_000_000_000 {
        announces_of(2..=12, 4, now, &mut core);
        times.extend(announce_times(&mut core, now, now + 299_999_999));
        now += 300_000_000;
    }
    let gaps: Vec<u64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(!gaps.is_empty() && gaps.iter().all(|&gap| gap == 300_000_000), "{times:?}");
    assert_eq!(core.peers().len(), 11, "peers that announce are not forgotten");
}

#[test]
fn peers_silent_for_four_announce_intervals_are_forgotten_and_no_longer_stretch_the_interval() {
    let mut core = announcer(1, 4);
    announces_of(2..=12, 4, 1, &mut core);
    assert_eq!(core.announce_interval_ns(), 300_000_000);
    // Peers 2 and 3 go on announcing; the other nine leave. Four intervals of 300 ms after their last word they
    // still count; at the first tick after that they are forgotten.
    let mut now = 300_000_000;
    while now <= 1_200_000_000 {
        announces_of(2..=3, 4, now, &mut core);
        core.tick(now);
        now += 100_000_000;
    }
    assert_eq!(core.peers().len(), 11, "silent for four intervals: still counted");
    announces_of(2..=3, 4, 1_500_000_001, &mut core);
    core.tick(1_500_000_001);
    assert_eq!(core.peers().collect::<Vec<_>>(), [AgentId(2), AgentId(3)]);
    assert_eq!(core.announce_interval_ns(), 100_000_000, "three agents: one group, the announce period");
    // One that comes back counts again.
    announces_of(4..=4, 4, 1_600_000_000, &mut core);
    assert_eq!(core.peers().len(), 3);
}

#[test]
fn with_no_announce_group_every_agent_announces_every_period_however_many_it_hears() {
    let mut core = announcer(1, 0);
    for peer in 2..=12 {
        let sends = announcer(peer, 0).tick(1).sends;
        deliver(&sends, &mut core);
    }
    assert_eq!(core.announce_interval_ns(), 100_000_000);
}

/// A life of agent `id` that joins (join wait 5 s), naming graph `graph` or none.
fn joiner(id: u32, nonce: u64, graph: Option<GraphId>) -> AgentCore {
    let config = AgentConfig { join_wait: Duration::from_secs(5), graph, ..AgentConfig::new(AgentId(id)) };
    AgentCore::new(config.protocol(), LifeSeed { nonce, recorded_incarnation: None, ..LifeSeed::default() }, None, 0)
}

/// A ready life of agent `id` of graph `graph` holding one node named `name`.
fn ready_with_node(id: u32, graph: u64, name: &str) -> AgentCore {
    let config = AgentConfig { join_wait: Duration::ZERO, graph: GraphId::new(graph), ..AgentConfig::new(AgentId(id)) };
    let mut core = AgentCore::new(
        config.protocol(),
        LifeSeed { nonce: u64::from(id), recorded_incarnation: None, ..LifeSeed::default() },
        None,
        0,
    );
    core.tick(0);
    core.write(1, |r, now| r.insert_node(now, NewNode::new("object", name)).map(|(_, d)| ((), vec![d]))).unwrap();
    core
}

fn foreign_events(events: &[Event]) -> Vec<GraphId> {
    events
        .iter()
        .filter_map(|event| match event {
            Event::ForeignGraph { graph, .. } => Some(*graph),
            _ => None,
        })
        .collect()
}

#[test]
fn a_delta_of_another_graph_is_refused_counted_and_reported_once_per_foreign_graph() {
    let mut a = ready_with_node(1, 0xa, "a");
    let before = a.replica().unwrap().digest();
    let mut events = Vec::new();
    for (id, graph) in [(2, 0xb), (3, 0xb), (4, 0xc)] {
        let mut other = ready_with_node(id, graph, "x");
        let (_, written) = other
            .write(2, |r, now| r.insert_node(now, NewNode::new("object", "intruder")).map(|(_, d)| ((), vec![d])))
            .unwrap();
        events.extend(deliver(&written.sends(), &mut a));
        events.extend(deliver(&other.tick(10).sends, &mut a));
    }
    assert_eq!(foreign_events(&events), [GraphId::new(0xb).unwrap(), GraphId::new(0xc).unwrap()], "{events:?}");
    assert_eq!(a.foreign_refused(), 6);
    assert_eq!(a.replica().unwrap().digest(), before, "nothing of a foreign graph was merged");
    let peers: Vec<AgentId> = a.peers().collect();
    assert!(peers.is_empty(), "agents of other graphs are not peers: {peers:?}");
}

#[test]
fn a_joiner_that_names_no_graph_takes_the_graph_it_joins() {
    let mut a = ready_with_node(1, 0xa, "a");
    let mut joiner = joiner(5, 50, None);
    let request = joiner.tick(1);
    assert_eq!(request.sends[0].graph, None, "its request names no graph");
    let answer = exchange(&request.sends, &mut a, 2);
    exchange(&answer.sends, &mut joiner, 3);
    assert_eq!(joiner.graph(), GraphId::new(0xa));
    assert_eq!(joiner.replica().unwrap().digest(), a.replica().unwrap().digest());
}

#[test]
fn a_joiner_that_hears_two_graphs_takes_the_first_answer_and_refuses_the_other() {
    let mut a = ready_with_node(1, 0xa, "a");
    let mut b = ready_with_node(2, 0xb, "b");
    let mut joiner = joiner(5, 50, None);
    // While it joins, both graphs write: their deltas are buffered with their graph.
    for (core, name) in [(&mut a, "a2"), (&mut b, "b2")] {
        let (_, written) = core
            .write(2, |r, now| r.insert_node(now, NewNode::new("object", name)).map(|(_, d)| ((), vec![d])))
            .unwrap();
        deliver(&written.sends(), &mut joiner);
    }
    let request = joiner.tick(3);
    let from_b = exchange(&request.sends, &mut b, 4);
    let from_a = exchange(&request.sends, &mut a, 4);
    let joined = exchange(&from_b.sends, &mut joiner, 5);
    let late = exchange(&from_a.sends, &mut joiner, 6);
    assert_eq!(joiner.graph(), GraphId::new(0xb));
    assert_eq!(joiner.replica().unwrap().digest(), b.replica().unwrap().digest());
    assert_eq!(foreign_events(&joined.events), [GraphId::new(0xa).unwrap()], "the buffered delta of A is refused");
    assert!(foreign_events(&late.events).is_empty(), "graph A was reported once: {:?}", late.events);
    assert_eq!(joiner.foreign_refused(), 2);
}

#[test]
fn a_joiner_that_names_a_graph_is_not_answered_by_another_graph_and_starts_it_alone() {
    let mut a = ready_with_node(1, 0xa, "a");
    let mut joiner = joiner(5, 50, GraphId::new(0xb));
    let request = joiner.tick(1);
    let answer = exchange(&request.sends, &mut a, 2);
    assert!(answer.sends.is_empty(), "{:?}", answer.sends);
    assert_eq!(foreign_events(&answer.events), [GraphId::new(0xb).unwrap()]);
    let mut out = Output::default();
    while !joiner.is_ready() {
        let now = joiner.next_deadline_ns();
        out = joiner.tick(now);
    }
    assert!(
        out.events
            .iter()
            .any(|e| matches!(e, Event::Ready { graph, alone: true, .. } if Some(*graph) == GraphId::new(0xb)))
    );
}

#[test]
fn a_life_that_starts_alone_naming_no_graph_creates_one_with_an_id_from_its_nonce() {
    let mut joiner = joiner(5, 77, None);
    let ready_ns = tick_until_ready(&mut joiner);
    assert_eq!(ready_ns, 5_000_000_000, "alone once the 5 s join wait is over");
    assert_eq!(joiner.graph(), Some(GraphId::from_nonce(77)));
}

/// Agents `a` and `b` talk, every message delivered, from `from_ns` for `rounds` of their announce period.
fn converse(a: &mut AgentCore, b: &mut AgentCore, from_ns: u64, rounds: u64) {
    for round in 0..rounds {
        let now = from_ns + round * 100_000_000;
        talk(a, b, now);
        talk(b, a, now);
    }
}

/// `x`'s tick at `now_ns` reaches `y`, and they answer each other until nothing more is said.
fn talk(x: &mut AgentCore, y: &mut AgentCore, now_ns: u64) {
    let mut sends = x.tick(now_ns).sends;
    while !sends.is_empty() {
        let replies = exchange(&sends, y, now_ns);
        sends = exchange(&replies.sends, x, now_ns).sends;
    }
}

#[test]
fn a_joiner_that_names_no_graph_and_gets_no_answer_starts_alone_in_the_one_graph_it_heard_and_merges_with_it() {
    let mut a = ready_with_node(1, 0xa, "a");
    let mut joiner = joiner(5, 50, None);
    // It hears A's announce and a delta of A, but neither of its requests nor A's answers get through (lost, or
    // a security handshake not yet done), until its join wait is over.
    deliver(&a.tick(0).sends, &mut joiner);
    let (_, written) =
        a.write(2, |r, now| r.insert_node(now, NewNode::new("object", "a2")).map(|(_, d)| ((), vec![d]))).unwrap();
    deliver(&written.sends(), &mut joiner);
    let mut started = Vec::new();
    while !joiner.is_ready() {
        let now = joiner.next_deadline_ns();
        started = joiner.tick(now).events;
    }
    assert!(started.iter().any(|e| matches!(e, Event::Ready { alone: true, .. })), "{started:?}");
    assert_eq!(joiner.graph(), GraphId::new(0xa), "it starts alone in A's graph, not one of its own");
    joiner
        .write(6_000_000_000, |r, now| r.insert_node(now, NewNode::new("object", "mine")).map(|(_, d)| ((), vec![d])))
        .unwrap();
    // Once they hear each other, anti-entropy merges the two replicas of one graph.
    converse(&mut a, &mut joiner, 6_100_000_000, 5);
    assert_eq!(a.foreign_refused() + joiner.foreign_refused(), 0);
    assert_eq!(joiner.replica().unwrap().digest(), a.replica().unwrap().digest());
    let names = |core: &AgentCore| core.replica().unwrap().nodes().count();
    assert_eq!((names(&a), names(&joiner)), (3, 3), "a, a2 and mine in both");
    assert!(joiner.graph_named(), "A's announces name the graph the joiner took unnamed");
}

/// A life of agent `id` that named no graph, heard nobody and started alone, holding one node named `name`.
fn alone_unnamed_with_node(id: u32, nonce: u64, name: &str) -> AgentCore {
    let mut core = joiner(id, nonce, None);
    let ready_ns = tick_until_ready(&mut core);
    core.write(ready_ns, |r, now| r.insert_node(now, NewNode::new("object", name)).map(|(_, d)| ((), vec![d])))
        .unwrap();
    assert_eq!((core.graph(), core.graph_named()), (Some(GraphId::from_nonce(nonce)), false));
    core
}

fn moves(events: &[Event]) -> Vec<(GraphId, GraphId, bool)> {
    events
        .iter()
        .filter_map(|event| match event {
            Event::GraphMoved { left, graph, named, .. } => Some((*left, *graph, *named)),
            _ => None,
        })
        .collect()
}

/// Like [`converse`], collecting the events of `b`.
fn converse_events(a: &mut AgentCore, b: &mut AgentCore, from_ns: u64, rounds: u64) -> Vec<Event> {
    let mut events = Vec::new();
    for round in 0..rounds {
        let now = from_ns + round * 100_000_000;
        events.extend(talk_events(a, b, now).1);
        events.extend(talk_events(b, a, now).0);
    }
    events
}

/// [`talk`], returning the events of `x` and of `y`.
fn talk_events(x: &mut AgentCore, y: &mut AgentCore, now_ns: u64) -> (Vec<Event>, Vec<Event>) {
    let (mut of_x, mut of_y) = (Vec::new(), Vec::new());
    let mut sends = x.tick(now_ns).sends;
    while !sends.is_empty() {
        let replies = exchange(&sends, y, now_ns);
        let back = exchange(&replies.sends, x, now_ns);
        of_y.extend(replies.events);
        of_x.extend(back.events);
        sends = back.sends;
    }
    (of_x, of_y)
}

#[test]
fn a_life_alone_in_an_unnamed_graph_moves_to_the_named_graph_it_hears_and_merges_with_it() {
    // The joiner heard nobody within its join wait (the agent of graph A stopped, cut off, or still
    // authenticating) and started a graph of its own; once they hear each other it moves to A, and A stays.
    let mut a = ready_with_node(1, 0xa, "a");
    let mut joiner = alone_unnamed_with_node(5, 50, "mine");
    let left = joiner.graph().unwrap();
    let events = converse_events(&mut a, &mut joiner, 6_000_000_000, 5);
    assert_eq!(moves(&events), [(left, GraphId::new(0xa).unwrap(), true)], "{events:?}");
    assert_eq!((a.graph(), joiner.graph(), joiner.graph_named()), (GraphId::new(0xa), GraphId::new(0xa), true));
    assert_eq!(joiner.replica().unwrap().digest(), a.replica().unwrap().digest());
    assert_eq!(a.replica().unwrap().nodes().count(), 2, "a and mine in both");
    assert!(a.foreign_graphs().is_empty() || a.foreign_graphs().contains(&left));
    assert!(joiner.foreign_graphs().is_empty(), "the graph it moved to is no longer foreign");
}

#[test]
fn two_lives_alone_in_unnamed_graphs_end_in_the_one_with_the_smaller_id_and_stay_unnamed() {
    let mut x = alone_unnamed_with_node(5, 50, "x");
    let mut y = alone_unnamed_with_node(6, 60, "y");
    let smaller = x.graph().min(y.graph());
    let events = converse_events(&mut x, &mut y, 6_000_000_000, 5);
    let events_x = converse_events(&mut y, &mut x, 6_500_000_000, 2);
    assert_eq!((x.graph(), y.graph()), (smaller, smaller));
    assert_eq!(moves(&events).len() + moves(&events_x).len(), 1, "one of them moved, once");
    assert!(!x.graph_named() && !y.graph_named());
    assert_eq!(x.replica().unwrap().digest(), y.replica().unwrap().digest());
    assert_eq!(x.replica().unwrap().nodes().count(), 2);
}

#[test]
fn a_named_graph_never_moves_to_an_unnamed_one_however_small_its_id() {
    let mut a = ready_with_node(1, u64::MAX, "a");
    let mut joiner = alone_unnamed_with_node(5, 50, "mine");
    let events = converse_events(&mut joiner, &mut a, 6_000_000_000, 3);
    assert!(moves(&events).is_empty(), "{events:?}");
    assert_eq!((a.graph(), joiner.graph()), (GraphId::new(u64::MAX), GraphId::new(u64::MAX)));
}

#[test]
fn a_joiner_that_names_no_graph_and_hears_agents_of_two_graphs_but_no_answer_starts_a_graph_of_its_own() {
    let mut a = ready_with_node(1, 0xa, "a");
    let mut b = ready_with_node(2, 0xb, "b");
    let mut joiner = joiner(5, 50, None);
    deliver(&a.tick(0).sends, &mut joiner);
    deliver(&b.tick(0).sends, &mut joiner);
    // A joiner's graph request names no graph it has: it is not counted as one heard.
    deliver(&self::joiner(6, 60, GraphId::new(0xc)).tick(0).sends, &mut joiner);
    let mut events = Vec::new();
    while !joiner.is_ready() {
        let now = joiner.next_deadline_ns();
        events.extend(joiner.tick(now).events);
    }
    assert_eq!(joiner.graph(), Some(GraphId::from_nonce(50)));
    let several = events.iter().find_map(|e| match e {
        Event::SeveralGraphsHeard { graphs } => Some(graphs.clone()),
        _ => None,
    });
    assert_eq!(several, Some(vec![GraphId::new(0xa).unwrap(), GraphId::new(0xb).unwrap()]), "{events:?}");
}

/// Ticks `core` at each of its deadlines until it is ready; returns when it became ready.
fn tick_until_ready(core: &mut AgentCore) -> u64 {
    let mut now = 0;
    while !core.is_ready() {
        now = core.next_deadline_ns().max(now);
        core.tick(now);
    }
    now
}

#[test]
fn a_joiner_stopped_while_it_joins_asks_again_when_it_resumes_and_starts_alone_only_after_the_rest_of_its_wait() {
    let mut joiner = joiner(5, 77, None);
    let requests =
        |out: &Output| out.sends.iter().filter(|s| matches!(s.message, Message::GraphRequest { .. })).count();
    assert_eq!(requests(&joiner.tick(0)), 1);
    assert_eq!(requests(&joiner.tick(200_000_000)), 1);
    // Stopped for 10 s (its next tick was due at 0.4 s): longer than its 5 s join wait, yet it heard nothing in it.
    let resumed = joiner.tick(10_400_000_000);
    assert!(!joiner.is_ready(), "a stopped joiner must not start alone the moment it resumes");
    assert_eq!(requests(&resumed), 1, "it asks again at once");
    // It had listened for 0.4 s before the stop: ticking at its deadlines, it starts alone 4.6 s after the
    // resume.
    assert_eq!(tick_until_ready(&mut joiner), 15_000_000_000);
    assert_eq!(joiner.graph(), Some(GraphId::from_nonce(77)));
}

/// The digest an announce in `out` carries: `None` for no announce, `Some(None)` for an announce without one.
fn announced_digest(out: &Output) -> Option<Option<[u8; 32]>> {
    out.sends.iter().find_map(|send| match &send.message {
        Message::Announce { digest, .. } => Some(*digest),
        _ => None,
    })
}

#[test]
fn an_announce_carries_the_digest_only_when_nothing_was_joined_since_the_previous_announce() {
    let mut core = announcer(1, 8);
    let write = |core: &mut AgentCore, now_ns: u64, name: &str| {
        core.write(now_ns, |r, now| r.insert_node(now, NewNode::new("object", name)).map(|(_, d)| ((), vec![d])))
            .unwrap();
    };
    // Frames keep coming: every announce meets a graph changed since the one before and hashes nothing.
    let mut now = 100_000_000;
    for frame in 0..5 {
        write(&mut core, now - 1, &format!("frame{frame}"));
        let out = core.tick(now);
        assert_eq!(announced_digest(&out), Some(None), "announce at {now} ns, after a write");
        now += 100_000_000;
    }
    // The writes stop: the next announce shows the still graph's digest, equal to the replica's own.
    let out = core.tick(now);
    let expected = core.replica().map(|r| r.digest().0);
    assert_eq!(announced_digest(&out), Some(expected), "announce at {now} ns, nothing joined since the last");
}

#[test]
fn a_peer_with_the_same_operations_and_another_digest_is_asked_for_a_whole_state_and_a_missing_digest_is_no_mismatch() {
    let mut a = announcer(1, 8);
    let applied = a.replica().unwrap().applied().clone();
    let announce = |digest| Input::Announce {
        from: AgentId(2),
        nonce: 2,
        replica: dsr::ReplicaId(2),
        applied: applied.clone(),
        digest,
        named: true,
    };
    let quiet = a.handle(1, graph_g(), announce(None));
    assert!(!quiet.events.iter().any(|e| matches!(e, Event::DigestMismatch { .. })), "{:?}", quiet.events);
    let other = a.handle(2, graph_g(), announce(Some([9; 32])));
    assert!(other.events.iter().any(|e| matches!(e, Event::DigestMismatch { peer: AgentId(2) })), "{:?}", other.events);
}
