//! Change callbacks (`Agent::on_change`): called once per visible change on the thread that made it visible,
//! with no lock held, so a callback may read and write the graph; removed callbacks are not called again.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent::{Agent, AgentConfig, AgentId, ChangeSignal, GraphId};
use dsr::{Change, Element, NewNode, attrs};
use transport::ManualClock;
use transport::inproc::{Bus, InProcTransport};

type BusAgent = Agent<InProcTransport>;

fn config(id: u32) -> AgentConfig {
    AgentConfig {
        join_wait: Duration::from_millis(300),
        join_retry: Duration::from_millis(20),
        answer_hold: Duration::from_millis(100),
        announce_period: Duration::from_millis(40),
        nonce: Some(u64::from(id) * 7919),
        graph: GraphId::new(0xCA11),
        ..AgentConfig::new(AgentId(id))
    }
}

/// Two agents on one bus, pumped by hand: agent 1 starts the graph, agent 2 joins it.
fn pair() -> (Arc<BusAgent>, Arc<BusAgent>, ManualClock) {
    let (bus, clock) = (Bus::new(), ManualClock::new(1_000_000_000));
    let start = |id| Arc::new(Agent::new(config(id), bus.attach(10_000), Arc::new(clock.clone())).unwrap());
    let (a, b) = (start(1), start(2));
    steps(&[&a], &clock, 400);
    steps(&[&a, &b], &clock, 50);
    assert!(b.is_ready(), "agent 2 joined");
    (a, b, clock)
}

fn steps(agents: &[&Arc<BusAgent>], clock: &ManualClock, n: usize) {
    for _ in 0..n {
        clock.advance(1_000_000);
        for agent in agents {
            agent.pump();
        }
    }
}

fn pos_x_updates(seen: &Mutex<Vec<ChangeSignal>>) -> Vec<ChangeSignal> {
    let seen = seen.lock().unwrap();
    seen.iter()
        .filter(|s| matches!(&s.change, Change::AttrUpdated { name, .. } if name.as_str() == "pos_x"))
        .cloned()
        .collect()
}

#[test]
fn a_callback_gets_each_remote_and_local_change_once_with_its_origin() {
    let (a, b, clock) = pair();
    let id = a.insert_node(NewNode::new("object", "cup")).unwrap();
    steps(&[&a, &b], &clock, 5);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = Arc::clone(&seen);
    b.on_change(move |signal| log.lock().unwrap().push(signal.clone()));
    for i in 0..10 {
        a.set_attr(id, attrs::POS_X, i as f32).unwrap();
        steps(&[&a, &b], &clock, 3);
    }
    let remote = pos_x_updates(&seen);
    assert_eq!(remote.len(), 10);
    assert!(remote.iter().all(|s| !s.local && s.origin == Some(AgentId(1))), "{remote:?}");
    b.set_attr(id, attrs::POS_X, 99.0f32).unwrap();
    let all = pos_x_updates(&seen);
    assert_eq!(all.len(), 11);
    assert!(all[10].local && all[10].origin == Some(AgentId(2)), "{:?}", all[10]);
}

#[test]
fn a_callback_may_write_to_the_graph_it_was_called_from_and_its_write_reaches_the_peer() {
    let (a, b, clock) = pair();
    let ping = a.insert_node(NewNode::new("object", "ping")).unwrap();
    let pong = a.insert_node(NewNode::new("object", "pong")).unwrap();
    steps(&[&a, &b], &clock, 5);
    let weak = Arc::downgrade(&b);
    b.on_change(move |signal| {
        let is_ping = matches!(&signal.change, Change::AttrUpdated { element: Element::Node(id), .. } if *id == ping);
        if let Some(b) = weak.upgrade().filter(|_| is_ping && !signal.local) {
            // Reads and writes from inside the callback: no lock of the agent is held.
            let x: f32 = b.attr(ping, attrs::POS_X).unwrap();
            b.set_attr(pong, attrs::POS_X, x + 1.0).unwrap();
        }
    });
    a.set_attr(ping, attrs::POS_X, 41.0f32).unwrap();
    steps(&[&a, &b], &clock, 5);
    assert_eq!(a.attr(pong, attrs::POS_X), Some(42.0f32), "the echo written in the callback came back");
    assert_eq!(b.attr(pong, attrs::POS_X), Some(42.0f32));
}

#[test]
fn a_removed_callback_is_not_called_again_and_removing_twice_says_so() {
    let (a, b, clock) = pair();
    let id = a.insert_node(NewNode::new("object", "cup")).unwrap();
    steps(&[&a, &b], &clock, 5);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = Arc::clone(&seen);
    let callback = b.on_change(move |signal| log.lock().unwrap().push(signal.clone()));
    a.set_attr(id, attrs::POS_X, 1.0f32).unwrap();
    steps(&[&a, &b], &clock, 3);
    assert!(b.remove_on_change(callback));
    assert!(!b.remove_on_change(callback), "already removed");
    a.set_attr(id, attrs::POS_X, 2.0f32).unwrap();
    steps(&[&a, &b], &clock, 3);
    assert_eq!(pos_x_updates(&seen).len(), 1);
    assert_eq!(b.attr(id, attrs::POS_X), Some(2.0f32), "the agent still joins what it no longer reports");
}

#[test]
fn changes_are_looked_for_only_while_someone_listens() {
    let (a, b, clock) = pair();
    assert!(!b.status().change_tracking, "nobody listens to a new agent");
    let id = a.insert_node(NewNode::new("object", "cup")).unwrap();
    steps(&[&a, &b], &clock, 5);

    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = Arc::clone(&seen);
    let callback = b.on_change(move |signal| log.lock().unwrap().push(signal.clone()));
    assert!(b.status().change_tracking, "a callback turns the look on");
    a.set_attr(id, attrs::POS_X, 1.0f32).unwrap();
    steps(&[&a, &b], &clock, 3);
    assert_eq!(pos_x_updates(&seen).len(), 1);

    assert!(b.remove_on_change(callback));
    assert!(!b.status().change_tracking, "removing the last callback turns it off");

    let subscription = b.subscribe(16);
    assert!(b.status().change_tracking, "a subscription turns it on");
    a.set_attr(id, attrs::POS_X, 2.0f32).unwrap();
    steps(&[&a, &b], &clock, 3);
    let got: Vec<ChangeSignal> = subscription.try_iter().collect();
    let pos_x = |s: &ChangeSignal| matches!(&s.change, Change::AttrUpdated { element: Element::Node(n), name } if *n == id && name.as_str() == "pos_x");
    assert!(got.iter().any(pos_x), "{got:?}");

    drop(subscription);
    assert!(b.status().change_tracking, "a dropped subscription is found at the next change");
    for x in [3.0f32, 4.0] {
        a.set_attr(id, attrs::POS_X, x).unwrap();
        steps(&[&a, &b], &clock, 3);
    }
    assert!(!b.status().change_tracking, "found gone, nobody listens");

    let log = Arc::clone(&seen);
    b.on_change(move |signal| log.lock().unwrap().push(signal.clone()));
    a.set_attr(id, attrs::POS_X, 5.0f32).unwrap();
    steps(&[&a, &b], &clock, 3);
    assert_eq!(pos_x_updates(&seen).len(), 2, "a new callback hears the next change");
    assert!(!a.status().change_tracking, "the writer never listened");
}
