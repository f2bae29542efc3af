//! The bridge's DDS path end to end inside one process, with a second `rustdds` participant as the ROS 2 side (the
//! same DDS implementation: the second vendor is Eclipse Cyclone DDS in `python/tests/test_ros2_bridge.py`). The
//! graph side is an agent on the in-process bus. Waits have deadlines; nothing is asserted about speed.

use std::sync::Arc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId};
use dsr::{Value, attrs};
use replay::ros2::{LaserScan, Ros2Message, decode};
use ros2bridge::config::{dds_topic, dds_type};
use ros2bridge::encode::{header_at, laser_scan};
use ros2bridge::qos::QosProfile;
use ros2bridge::raw::{RawCdr, RawCdrAdapter};
use ros2bridge::{BridgeConfig, Ros2Bridge};
use rustdds::{DomainParticipantBuilder, TopicKind};
use transport::SystemClock;
use transport::inproc::Bus;

const DOMAIN: u16 = 93;
const LASER: &str = "sensor_msgs/msg/LaserScan";

fn wait_until(what: &str, mut condition: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(60);
    while !condition() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn scan(stamp_ns: u64, ranges: Vec<f32>) -> LaserScan {
    LaserScan {
        header: header_at(stamp_ns, "laser"),
        angle_min: -0.5,
        angle_max: 0.5,
        angle_increment: 0.5,
        time_increment: 0.0,
        scan_time: 0.0,
        range_min: 0.0,
        range_max: 30.0,
        ranges,
        intensities: vec![],
    }
}

#[test]
fn a_scan_from_a_ros2_publisher_reaches_the_graph_and_comes_back_out_and_a_truncated_one_is_counted() {
    let config = BridgeConfig::parse(
        &format!(
            r#"
            ros_domain = {DOMAIN}
            [[in]]
            topic = "/scan"
            type = "{LASER}"
            qos = "default"
            [[laser_out]]
            node = "/scan"
            topic = "/scan_out"
            rate_hz = 1000.0
            qos = "default"
            "#
        ),
        "live.rs",
    )
    .unwrap();
    let bus = Bus::new();
    let agent_config = AgentConfig { join_wait: Duration::from_millis(50), ..AgentConfig::new(AgentId(7)) };
    let agent = Arc::new(Agent::start(agent_config, bus.attach(1024), Arc::new(SystemClock)).unwrap());
    assert!(agent.wait_ready(Duration::from_secs(30)));
    let bridge = Ros2Bridge::start(&config, Arc::clone(&agent)).unwrap();

    // The ROS 2 side.
    let ros = DomainParticipantBuilder::new(DOMAIN).build().unwrap();
    let qos = QosProfile::Default.policies();
    let topic = |name: &str| ros.create_topic(dds_topic(name), dds_type(LASER), &qos, TopicKind::NoKey).unwrap();
    let writer = ros
        .create_publisher(&qos)
        .unwrap()
        .create_datawriter_no_key::<RawCdr, RawCdrAdapter>(&topic("/scan"), Some(qos.clone()))
        .unwrap();
    let reader = ros
        .create_subscriber(&qos)
        .unwrap()
        .create_simple_datareader_no_key::<RawCdr, RawCdrAdapter>(&topic("/scan_out"), Some(qos.clone()))
        .unwrap();

    let sent = scan(1_700_000_000_000_000_000, vec![1.0, 2.0, 4.5]);
    let written = || bridge.status().inputs[0].written;
    wait_until("the scan in the graph", || {
        writer.write(RawCdr(laser_scan(&sent)), None).unwrap();
        written() >= 1
    });
    let dists =
        agent.read(|replica| replica.node_by_name("/scan").and_then(|n| n.attr(attrs::LASER_DISTS.name()).cloned()));
    assert_eq!(dists.flatten(), Some(Value::VecF32(dsr::Numbers::from([1000.0f32, 2000.0, 4500.0]))));

    let mut back = None;
    wait_until("the scan back out", || {
        while let Ok(Some(change)) = reader.try_take_one() {
            back = Some(change.into_value().0);
        }
        back.is_some()
    });
    let Some(Ros2Message::LaserScan(got)) = decode(LASER, &back.unwrap()).unwrap() else { panic!("not a scan") };
    assert_eq!((got.ranges.clone(), got.header.clone()), (sent.ranges.clone(), sent.header.clone()));
    assert_eq!((got.angle_min, got.angle_max, got.angle_increment), (-0.5, 0.5, 0.5));

    let cut = laser_scan(&sent).slice(..30);
    writer.write(RawCdr(cut), None).unwrap();
    wait_until("the truncated scan to be counted", || bridge.status().inputs[0].malformed >= 1);
    let status = bridge.status();
    assert!(status.inputs[0].last_error.as_deref().unwrap_or("").contains("LaserScan"), "{status:?}");
    assert_eq!(status.outputs[0].errors, 0);
    bridge.stop();
}
