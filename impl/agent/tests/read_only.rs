//! The protocol core alone: which channel each message takes (asking alone on the requests channel, the one a
//! read-only participant may write), the refusal of anything else that arrives there, and a read-only life that
//! joins, follows the graph and changes nothing.

use std::time::Duration;

use agent::core::{AgentCore, Event, Input, LifeSeed, Output, Send, WriteRefusal};
use agent::envelope::{Envelope, Message};
use agent::{AgentConfig, AgentId, GraphId};
use dsr::NewNode;
use transport::Channel;

const GRAPH: u64 = 0x7e;
const SECOND: u64 = 1_000_000_000;

/// A life of agent `id` of the graph; `join_wait` zero starts it alone at its first tick.
fn life(id: u32, join_wait: Duration, read_only: bool) -> AgentCore {
    let config = AgentConfig { join_wait, graph: GraphId::new(GRAPH), read_only, ..AgentConfig::new(AgentId(id)) };
    AgentCore::new(
        config.protocol(),
        LifeSeed { nonce: u64::from(id) << 8, recorded_incarnation: None, ..LifeSeed::default() },
        None,
        0,
    )
}

/// A writer alone with one node named `name`.
fn writer_with_node(id: u32, name: &str) -> AgentCore {
    let mut core = life(id, Duration::ZERO, false);
    core.tick(0);
    core.write(1, |r, now| r.insert_node(now, NewNode::new("object", name)).map(|(_, d)| ((), vec![d]))).unwrap();
    core
}

/// Hands `send` to `to` as a running agent does, on the channel `channel`: admitted by channel, decoded, handled.
fn receive(send: &Send, channel: Channel, to: &mut AgentCore, now_ns: u64) -> Output {
    let Envelope { graph, message } = Envelope::decode(&send.encode()).unwrap();
    let mut out = Output::default();
    if !to.admit_channel(channel, &message, &mut out) {
        return out;
    }
    let input = Input::decode(message).input.expect("a protocol message");
    let handled = to.handle(now_ns, graph, input);
    out.sends.extend(handled.sends);
    out.events.extend(handled.events);
    out.changes.extend(handled.changes);
    out
}

/// Hands every message of `sends` to `to` on its own channel; returns everything `to` answered.
fn exchange(sends: &[Send], to: &mut AgentCore, now_ns: u64) -> Output {
    let mut replies = Output::default();
    for send in sends {
        let out = receive(send, send.channel, to, now_ns);
        replies.sends.extend(out.sends);
        replies.events.extend(out.events);
    }
    replies
}

fn misrouted(events: &[Event]) -> Vec<(&'static str, bool)> {
    events
        .iter()
        .filter_map(|event| match event {
            Event::Misrouted { kind, first, .. } => Some((*kind, *first)),
            _ => None,
        })
        .collect()
}

#[test]
fn asking_travels_on_the_requests_channel_and_answers_on_sync() {
    let mut writer = writer_with_node(1, "a");
    let mut joiner = life(2, Duration::from_secs(5), false);
    let request = joiner.tick(0).sends;
    assert_eq!(
        request.iter().map(|s| (s.message.kind(), s.channel)).collect::<Vec<_>>(),
        [("graph-request", Channel::Requests)]
    );
    let answer = exchange(&request, &mut writer, 10).sends;
    assert_eq!(
        answer.iter().map(|s| (s.message.kind(), s.channel)).collect::<Vec<_>>(),
        [("graph-answer", Channel::Sync)]
    );
    exchange(&answer, &mut joiner, 20);
    assert!(joiner.is_ready());
    // The writer writes again; its announce shows the joiner what it lacks, and the joiner asks for it.
    writer.write(30, |r, now| r.insert_node(now, NewNode::new("object", "b")).map(|(_, d)| ((), vec![d]))).unwrap();
    let announce = writer.tick(SECOND).sends;
    assert_eq!(
        announce.iter().map(|s| (s.message.kind(), s.channel)).collect::<Vec<_>>(),
        [("announce", Channel::Requests)]
    );
    let ask = exchange(&announce, &mut joiner, SECOND).sends;
    assert_eq!(
        ask.iter().map(|s| (s.message.kind(), s.channel)).collect::<Vec<_>>(),
        [("missing-request", Channel::Requests)]
    );
    let deltas = exchange(&ask, &mut writer, SECOND).sends;
    assert!(!deltas.is_empty() && deltas.iter().all(|s| s.channel == Channel::Sync), "{deltas:?}");
    for send in [&request[0], &announce[0], &ask[0]] {
        assert!(send.message.asks() && send.message.channel() == Channel::Requests);
    }
    for send in [&answer[0], &deltas[0]] {
        assert!(!send.message.asks() && send.message.channel() == Channel::Sync);
    }
}

#[test]
fn a_delta_on_the_requests_channel_is_refused_counted_and_never_applied() {
    let mut agent = writer_with_node(1, "a");
    let before = agent.replica().unwrap().digest();
    let mut intruder = writer_with_node(5, "x");
    let (_, written) = intruder
        .write(2, |r, now| r.insert_node(now, NewNode::new("object", "intruder")).map(|(_, d)| ((), vec![d])))
        .unwrap();
    let delta = &written.sends()[0];
    assert_eq!(delta.channel, Channel::Updates);
    let first = receive(delta, Channel::Requests, &mut agent, 10);
    let again = receive(delta, Channel::Requests, &mut agent, 11);
    assert_eq!(misrouted(&first.events), [("delta", true)]);
    assert_eq!(misrouted(&again.events), [("delta", false)]);
    assert!(first.sends.is_empty() && first.changes.is_empty());
    assert_eq!(agent.misrouted_refused(), 2);
    assert_eq!(agent.replica().unwrap().digest(), before, "nothing on the requests channel was applied");
    let peers: Vec<AgentId> = agent.peers().collect();
    assert!(peers.is_empty(), "a refused message makes no peer: {peers:?}");

    // Answers are refused there too: a snapshot, or missing deltas, could carry anything.
    let mut joiner = life(6, Duration::from_secs(5), false);
    let answer = exchange(&joiner.tick(0).sends, &mut intruder, 20).sends;
    assert_eq!(answer[0].message.kind(), "graph-answer");
    let mut fresh = life(7, Duration::from_secs(5), false);
    let refused = receive(&answer[0], Channel::Requests, &mut fresh, 30);
    assert_eq!(misrouted(&refused.events), [("graph-answer", true)]);
    assert!(!fresh.is_ready());

    // The same delta on its own channel is applied.
    receive(delta, Channel::Updates, &mut agent, 40);
    assert_ne!(agent.replica().unwrap().digest(), before);
    assert_eq!(agent.misrouted_refused(), 2);
}

#[test]
fn a_read_only_life_joins_follows_the_graph_and_publishes_nothing_but_requests() {
    let mut writer = writer_with_node(1, "a");
    let mut reader = life(9, Duration::from_millis(100), true);
    // Long past its join wait, with nobody answering, it still asks and never starts alone.
    for at in [0, SECOND, 10 * SECOND] {
        let out = reader.tick(at);
        assert!(!reader.is_ready(), "a read-only life started alone");
        assert!(out.sends.iter().all(|s| s.channel == Channel::Requests), "{:?}", out.sends);
    }
    assert!(reader.next_deadline_ns() < u64::MAX, "it keeps asking");
    let request = reader.tick(20 * SECOND).sends;
    let answer = exchange(&request, &mut writer, 20 * SECOND).sends;
    exchange(&answer, &mut reader, 20 * SECOND);
    assert!(reader.is_ready());
    assert_eq!(reader.replica().unwrap().digest(), writer.replica().unwrap().digest());

    // It never announces, and answers neither a joiner's graph request nor a missing-request.
    assert!(reader.tick(30 * SECOND).sends.is_empty());
    assert_eq!(reader.next_deadline_ns(), u64::MAX);
    let mut joiner = life(3, Duration::from_secs(5), false);
    let asked = joiner.tick(30 * SECOND).sends;
    assert!(exchange(&asked, &mut reader, 30 * SECOND).sends.is_empty(), "a read-only life answered a join");
    let fresh = writer_with_node(4, "b");
    let applied = fresh.replica().unwrap().applied().clone();
    let missing = Send {
        channel: Channel::Requests,
        message: Message::MissingRequest { from: AgentId(4), to: AgentId(9), applied, full: true },
        dest: agent::core::Dest::All,
        graph: GraphId::new(GRAPH),
        sample: None,
    };
    assert!(receive(&missing, Channel::Requests, &mut reader, 31 * SECOND).sends.is_empty());

    // It follows the writer: a new write reaches it by the announce and its missing-request.
    writer.write(40, |r, now| r.insert_node(now, NewNode::new("object", "c")).map(|(_, d)| ((), vec![d]))).unwrap();
    let announce = writer.tick(40 * SECOND).sends;
    let ask = exchange(&announce, &mut reader, 40 * SECOND).sends;
    assert!(ask.iter().all(|s| s.channel == Channel::Requests) && !ask.is_empty(), "{ask:?}");
    exchange(&exchange(&ask, &mut writer, 40 * SECOND).sends, &mut reader, 40 * SECOND);
    assert_eq!(reader.replica().unwrap().digest(), writer.replica().unwrap().digest());

    // Local edits are refused, and the graph is unchanged.
    let before = reader.replica().unwrap().digest();
    let refused =
        reader.write(41, |r, now| r.insert_node(now, NewNode::new("object", "z")).map(|(_, d)| ((), vec![d])));
    assert!(matches!(refused, Err(WriteRefusal::ReadOnly)), "{refused:?}");
    assert_eq!(reader.replica().unwrap().digest(), before);
}
