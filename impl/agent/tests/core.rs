//! The protocol core alone (no transport, no threads): how a life chooses its replica id, and what happens when a
//! replica id is reused anyway.

use std::time::Duration;

use agent::core::{AgentCore, Event, Input, LifeSeed, Output};
use agent::envelope::Message;
use agent::{AgentConfig, AgentId};
use dsr::NewNode;

/// A life of agent 3 that starts alone at its first tick.
fn alone(nonce: u64, recorded_incarnation: Option<u32>) -> (AgentCore, Output) {
    let config = AgentConfig { join_wait: Duration::ZERO, ..AgentConfig::new(AgentId(3)) };
    let mut core = AgentCore::new(config.protocol(), LifeSeed { nonce, recorded_incarnation }, None, 0);
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
        let message = Message::decode(&send.message.encode()).unwrap();
        if let Some(input) = Input::decode(message).input {
            events.extend(to.handle(1, input).events);
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
