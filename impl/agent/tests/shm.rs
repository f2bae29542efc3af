//! Agents over shared memory (`transport::shm::ShmTransport`, issue 20): real iceoryx2 services in this process,
//! the agents pumped by hand on one manual clock, so every round is deterministic (shared-memory delivery is done
//! when `publish` returns). The claims are about convergence and the counters, never about speed.

use std::sync::Arc;
use std::time::Duration;

use agent::{Agent, AgentConfig, AgentId, GraphId};
use dsr::{NewNode, Numbers, Value, attrs};
use transport::shm::{ShmSettings, ShmTransport};
use transport::{Clock, EndpointId, ManualClock};

type ShmAgent = Agent<ShmTransport>;

fn agent(prefix: &str, id: u32, nonce: u64, clock: &ManualClock) -> ShmAgent {
    let settings = ShmSettings { max_sample_bytes: 1 << 20, ..ShmSettings::default() };
    let transport = ShmTransport::open(prefix, EndpointId(u128::from(nonce)), &settings).expect("shared memory");
    // One named graph: two agents that start alone at once would otherwise create two graphs.
    let config = AgentConfig { nonce: Some(nonce), graph: GraphId::new(0x5a), ..AgentConfig::new(AgentId(id)) };
    Agent::new(config, transport, Arc::new(clock.clone()) as Arc<dyn Clock>).expect("agent")
}

/// Rounds of 50 ms until `done` holds; panics with `what` after 400 rounds (20 s of manual time).
fn rounds_until(clock: &ManualClock, agents: &[&ShmAgent], what: &str, done: impl Fn() -> bool) {
    for _ in 0..400 {
        clock.advance(Duration::from_millis(50).as_nanos() as u64);
        for a in agents {
            a.pump();
        }
        if done() {
            return;
        }
    }
    panic!("not within 400 rounds: {what}");
}

/// Two agents on lanes named after `test`, with `nonces`, pumped until both are ready.
fn two_ready(test: &str, nonces: [u64; 2]) -> (ManualClock, ShmAgent, ShmAgent) {
    let prefix = format!("cortex/test/{}/{test}", std::process::id());
    let clock = ManualClock::new(1_000_000_000);
    let a = agent(&prefix, 1, nonces[0], &clock);
    let b = agent(&prefix, 2, nonces[1], &clock);
    rounds_until(&clock, &[&a, &b], "both ready", || a.is_ready() && b.is_ready());
    (clock, a, b)
}

fn same_graph(a: &ShmAgent, b: &ShmAgent) -> bool {
    a.is_ready() && b.is_ready() && a.digest().is_some() && a.digest() == b.digest()
}

#[test]
fn two_agents_over_shared_memory_converge_and_the_samples_went_through_it() {
    let (clock, a, b) = two_ready("agents-converge", [101, 102]);
    a.insert_node(NewNode::new("object", "cup").with_attr("pos_x", 1.0f32)).expect("write");
    b.insert_node(NewNode::new("object", "plate").with_attr("pos_x", 2.0f32)).expect("write");
    rounds_until(&clock, &[&a, &b], "equal graphs", || same_graph(&a, &b));
    assert!(b.status().transport.samples_received > 0, "b received through shared memory");
    assert!(a.status().transport.samples_received > 0, "a received through shared memory");
}

#[test]
fn a_late_joiner_and_a_restarted_agent_get_the_graph_over_shared_memory() {
    let prefix = format!("cortex/test/{}/agents-late", std::process::id());
    let clock = ManualClock::new(1_000_000_000);
    let a = agent(&prefix, 1, 201, &clock);
    rounds_until(&clock, &[&a], "a ready alone", || a.is_ready());
    for i in 0..20 {
        a.insert_node(NewNode::new("object", &format!("o{i}")).with_attr("pos_x", i as f32)).expect("write");
    }
    let late = agent(&prefix, 2, 202, &clock);
    rounds_until(&clock, &[&a, &late], "the late joiner has a's graph", || same_graph(&a, &late));
    assert_eq!(late.status().nodes, a.status().nodes);

    // The joiner dies (its ports go with it) and comes back as a new life, while a writes on.
    drop(late);
    a.insert_node(NewNode::new("object", "while-away")).expect("write");
    let back = agent(&prefix, 2, 203, &clock);
    rounds_until(&clock, &[&a, &back], "the new life has a's graph", || same_graph(&a, &back));
    back.insert_node(NewNode::new("object", "after-restart")).expect("write");
    rounds_until(&clock, &[&a, &back], "a has the new life's write", || same_graph(&a, &back));
}

/// A point cloud written by one agent is read in place by the other: its columns are views of the sample's buffer
/// (the shared-memory chunk, leased), not copies. The envelope before the delta does not spoil their alignment, as
/// the encoder places them from the sample's start.
#[test]
fn a_point_cloud_arrives_over_shared_memory_as_views_not_copies() {
    let (clock, a, b) = two_ready("agents-cloud", [301, 302]);
    let lidar = a.insert_node(NewNode::new("lidar", "ouster")).expect("write");
    let column = |k: f32| -> Numbers<f32> { (0..65_536).map(|i| i as f32 * k).collect() };
    let cloud = [("lidar_points_x", column(1.0)), ("lidar_points_y", column(-0.5)), ("lidar_points_z", column(0.25))];
    a.set_attrs(lidar, cloud.iter().map(|(name, values)| (*name, Value::VecF32(values.clone())))).expect("write");
    let has_cloud = || b.attr(lidar, attrs::LIDAR_POINTS_Z).is_some_and(|z| z.len() == 65_536);
    rounds_until(&clock, &[&a, &b], "b has the cloud", has_cloud);
    for (key, (name, values)) in
        [attrs::LIDAR_POINTS_X, attrs::LIDAR_POINTS_Y, attrs::LIDAR_POINTS_Z].into_iter().zip(&cloud)
    {
        let got = b.attr(lidar, key).expect("the column");
        assert_eq!(&got, values, "{name}");
        assert!(got.is_view() || cfg!(target_endian = "big"), "{name} was copied on receipt");
    }
    // The receiver's status counts them so (the graph it joined with had no large values).
    let status = b.status();
    if cfg!(target_endian = "little") {
        assert_eq!((status.large_values_shared, status.large_values_copied), (3, 0));
    }
}

#[test]
fn an_agent_driven_by_its_applications_thread_handles_samples_and_runs_callbacks_there() {
    let (_clock, a, b) = two_ready("driven-callbacks", [111, 112]);
    let seen_on = Arc::new(std::sync::Mutex::new(Vec::new()));
    let record = Arc::clone(&seen_on);
    b.on_change(move |_| record.lock().expect("record").push(std::thread::current().id()));
    // A write made while b's application thread waits in `pump_wait` wakes it.
    let cup = std::thread::scope(|scope| {
        let writer = scope.spawn(|| {
            std::thread::sleep(Duration::from_millis(20));
            a.insert_node(NewNode::new("object", "cup").with_attr("pos_x", 1.0f32)).expect("write")
        });
        let mut handled = 0;
        for _ in 0..100 {
            handled += b.pump_wait(Duration::from_secs(10));
            if b.node_by_name("cup").is_some() {
                break;
            }
        }
        assert!(handled >= 1, "b handled the write's sample");
        writer.join().expect("writer")
    });
    assert_eq!(b.node(cup).map(|n| n.name), Some("cup".to_owned()));
    let threads = seen_on.lock().expect("record").clone();
    assert!(!threads.is_empty(), "b's callback ran");
    assert!(threads.iter().all(|t| *t == std::thread::current().id()), "every callback ran on the pumping thread");
}

#[test]
fn pump_wait_returns_after_its_timeout_with_nothing_to_do_and_does_the_periodic_work_once_due() {
    let (clock, a, b) = two_ready("driven-periodic", [121, 122]);
    while a.pump() + b.pump() > 0 {}
    // Nothing sent, nothing due on the manual clock: the wait ends at its timeout with nothing handled.
    assert_eq!(b.pump_wait(Duration::from_millis(20)), 0);
    assert_eq!(a.pump(), 0, "b sent nothing while nothing was due");
    // Past the announce interval, b's periodic work is due: the call does it at once, and a hears b's announce.
    clock.advance(Duration::from_secs(5).as_nanos() as u64);
    b.pump_wait(Duration::from_secs(60));
    assert!(a.pump() > 0, "b announced from pump_wait");
}

#[test]
fn pump_wait_on_a_started_agent_leaves_the_samples_to_its_threads() {
    let prefix = format!("cortex/test/{}/driven-started", std::process::id());
    let settings = ShmSettings { max_sample_bytes: 1 << 20, ..ShmSettings::default() };
    let open = |nonce: u64| ShmTransport::open(&prefix, EndpointId(u128::from(nonce)), &settings).expect("shm");
    let config = |id, nonce| AgentConfig {
        nonce: Some(nonce),
        graph: GraphId::new(0x5b),
        join_wait: Duration::from_millis(20),
        ..AgentConfig::new(AgentId(id))
    };
    let clock = || Arc::new(transport::SystemClock) as Arc<dyn Clock>;
    let a = Agent::start(config(1, 131), open(131), clock()).expect("a");
    assert!(a.wait_ready(Duration::from_secs(10)), "a ready");
    let b = Agent::start(config(2, 132), open(132), clock()).expect("b");
    assert!(b.wait_ready(Duration::from_secs(10)), "b ready");
    let cup = a.insert_node(NewNode::new("object", "cup")).expect("write");
    let mut handled_here = 0;
    for _ in 0..1000 {
        handled_here += b.pump_wait(Duration::from_millis(10));
        if b.node(cup).is_some() {
            break;
        }
    }
    assert!(b.node(cup).is_some(), "b's threads received the write");
    assert_eq!(handled_here, 0, "the started agent's samples are handled by its threads, not by pump_wait");
}
