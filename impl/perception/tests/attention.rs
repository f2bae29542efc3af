//! Attention picks the stimulus its rules say, and the attention role's search/track FSM switches at run time
//! (the scanner shuts down quietly while tracking), writing the gaze target into the graph.

use bica::prelude::*;
use dsr::{EdgeKey, NewNode, NodeId, Replica, ReplicaId, attrs};
use perception::attention::{Attention, Requirement, Scanner, Stimulus, StimulusKind};
use perception::behaviour::{SearchTrack, SearchTrackFsm};
use perception::graph::share_replica;
use perception::roles;

fn stimulus(kind: StimulusKind, track_id: u64, salience: f64) -> Stimulus {
    Stimulus { kind, track_id, frame: NodeId(1), point_mm: [0.0; 3], salience }
}

fn requirement(kind: StimulusKind, priority: u8) -> Requirement {
    Requirement { requester: "test", kind, priority }
}

#[test]
fn attention_follows_priority_then_order_then_hysteresis_then_salience() {
    let ball = StimulusKind::Blob { class: 0 };
    let obstacle = StimulusKind::Obstacle;
    let attention = Attention::new();
    // Rule 2: the higher priority kind wins even if less salient.
    let found = vec![
        (requirement(obstacle, 1), vec![stimulus(obstacle, 1, 100.0)]),
        (requirement(ball, 5), vec![stimulus(ball, 7, 1.0)]),
    ];
    assert_eq!(attention.choose(&found).unwrap().kind, ball);
    // A kind without stimuli does not govern: fall to the next one.
    let found = vec![(requirement(ball, 5), vec![]), (requirement(obstacle, 1), vec![stimulus(obstacle, 1, 1.0)])];
    assert_eq!(attention.choose(&found).unwrap().kind, obstacle);
    // Equal priorities: the kind required first.
    let found = vec![
        (requirement(obstacle, 3), vec![stimulus(obstacle, 1, 1.0)]),
        (requirement(ball, 3), vec![stimulus(ball, 2, 50.0)]),
    ];
    assert_eq!(attention.choose(&found).unwrap().kind, obstacle);
    // Rule 3: most salient; ties to the lowest track id.
    let found =
        vec![(requirement(ball, 1), vec![stimulus(ball, 4, 10.0), stimulus(ball, 3, 30.0), stimulus(ball, 2, 30.0)])];
    assert_eq!(attention.choose(&found).unwrap().track_id, 2);
    assert!(attention.choose(&[(requirement(ball, 1), vec![])]).is_none());
}

#[test]
fn attention_keeps_its_target_while_it_exists() {
    // Run attention in a runtime with a fake source to exercise hysteresis through real steps.
    struct Source(Vec<Stimulus>);
    impl Component for Source {
        fn step(&mut self, _: &mut StepContext<'_>) -> Result<(), BicaError> {
            Ok(())
        }
    }
    impl perception::attention::StimulusSource for Source {
        fn stimuli(&self, kind: StimulusKind) -> Vec<Stimulus> {
            self.0.iter().filter(|s| s.kind == kind).cloned().collect()
        }
    }
    let ball = StimulusKind::Blob { class: 0 };
    let mut runtime = Runtime::new(RuntimeConfig::default(), VirtualClock::new(0));
    runtime.register(Source(vec![stimulus(ball, 1, 10.0)]), 10).unwrap();
    let mut attention = Attention::new().with_source::<Source>(ball);
    attention.require("test", ball, 1);
    runtime.register(attention, 10).unwrap();
    runtime.activate::<Attention>().unwrap();
    runtime.run_until(5).unwrap();
    assert_eq!(runtime.registry().get::<Attention>().unwrap().target().unwrap().track_id, 1);
    // A more salient stimulus appears: attention stays on track 1 while it exists...
    runtime.registry_mut().get_mut::<Source>().unwrap().0.push(stimulus(ball, 2, 99.0));
    runtime.run_until(15).unwrap();
    assert_eq!(runtime.registry().get::<Attention>().unwrap().target().unwrap().track_id, 1);
    // ...and moves when it goes.
    runtime.registry_mut().get_mut::<Source>().unwrap().0.remove(0);
    runtime.run_until(25).unwrap();
    assert_eq!(runtime.registry().get::<Attention>().unwrap().target().unwrap().track_id, 2);
    // Released requirement: no target.
    runtime.registry_mut().get_mut::<Attention>().unwrap().release("test");
    runtime.run_until(35).unwrap();
    assert!(runtime.registry().get::<Attention>().unwrap().target().is_none());
}

#[test]
fn attention_role_switches_between_search_and_track_and_writes_the_gaze_target() {
    let (replica, graph) = share_replica(Replica::new(ReplicaId(3)));
    let (head, laser) = {
        let mut g = graph.borrow_mut();
        let world = g.insert_node(1, NewNode::new("world", "world")).unwrap();
        let head = g.insert_node(1, NewNode::new("head", "head")).unwrap();
        let laser = g.insert_node(1, NewNode::new("laser", "laser")).unwrap();
        g.set_rt(1, world, head, [0.0, 0.0, 1200.0], [0.0; 3]).unwrap();
        g.set_rt(1, world, laser, [100.0, 0.0, 300.0], [0.0; 3]).unwrap();
        (head, laser)
    };
    let clock = VirtualClock::new(0);
    let mut runtime = Runtime::new(RuntimeConfig::default(), clock.clone());
    roles::attention(&mut runtime, graph.clone(), "head", StimulusKind::Obstacle, 50).unwrap();
    let state = |runtime: &Runtime<VirtualClock>| runtime.registry().get::<SearchTrackFsm>().unwrap().current_state();
    let scans = |runtime: &Runtime<VirtualClock>| runtime.registry().get::<Scanner>().unwrap().runs();
    runtime.run_until(500_000_000).unwrap();
    assert_eq!(state(&runtime), SearchTrack::Search);
    assert!(scans(&runtime) >= 9, "the scanner sweeps while searching");
    assert!(replica.borrow().node_by_name("gaze_target").is_some());
    // A laser detector (another agent) inserts an obstacle 2 m ahead of the laser.
    let obstacle = {
        let mut g = graph.borrow_mut();
        let obstacle = g.insert_node(600_000_000, NewNode::new("obstacle", "obstacle_laser_1")).unwrap();
        g.set_rt(600_000_000, laser, obstacle, [2000.0, 500.0, 0.0], [0.0; 3]).unwrap();
        obstacle
    };
    runtime.run_until(1_000_000_000).unwrap();
    assert_eq!(state(&runtime), SearchTrack::Track);
    let scans_when_tracking = scans(&runtime);
    {
        let r = replica.borrow();
        let gaze = r.node_by_name("gaze_target").unwrap().id();
        let edge = r.edge(&EdgeKey::new(head, gaze, "RT")).unwrap();
        let t = edge.get(attrs::RT_TRANSLATION).unwrap();
        // Obstacle in world: (2100, 500, 300); in the head's frame: (2100, 500, -900).
        assert_eq!(&t[..], &[2100.0, 500.0, -900.0]);
    }
    runtime.run_until(2_000_000_000).unwrap();
    assert_eq!(state(&runtime), SearchTrack::Track);
    assert_eq!(scans(&runtime), scans_when_tracking, "the scanner is quiet while tracking");
    // The obstacle goes: after a second without a target the behaviour searches again.
    graph.borrow_mut().delete_node(2_000_000_000, obstacle).unwrap();
    runtime.run_until(2_900_000_000).unwrap();
    assert_eq!(state(&runtime), SearchTrack::Track);
    runtime.run_until(3_200_000_000).unwrap();
    assert_eq!(state(&runtime), SearchTrack::Search);
    runtime.run_until(3_600_000_000).unwrap();
    assert!(scans(&runtime) > scans_when_tracking);
    assert_eq!(runtime.step_failures(), 0);
}
