//! The In direction's core: samples of ROS 2 topics become graph operations through `replay`'s [`Bridge`], exactly
//! as a logged message of the same topic would (one decoder set for logs and live topics). A sample is offered as
//! raw CDR bytes with its topic's index; the topic's rate limit is applied on an injected arrival time; malformed
//! samples (truncated CDR, another type's bytes, a representation other than plain CDR) are counted per topic with
//! the last reason and logged (the first few one by one, then every thousandth), never a panic. No I/O, thread or
//! clock here: [`crate::runtime`] does those.

use std::sync::Arc;

use bytes::Bytes;
use dsr::{Delta, Replica};
use replay::{Bridge, BridgeOptions, BridgeStats, Channel, Message, Schema};
use serde::Serialize;

use crate::config::InTopic;

/// Malformed samples of a topic logged one by one; after these, every thousandth (all are counted).
const LOGGED_MALFORMED: u64 = 10;
/// How many characters of a failure reason a status line keeps.
const REASON_CHARS: usize = 240;

/// What happened on one input topic.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct InCounters {
    /// The ROS 2 topic.
    pub topic: String,
    /// The node written (TF topics write frame nodes).
    pub node: String,
    /// Samples received (every sample rustdds handed over, good or bad).
    pub received: u64,
    /// Samples written into the graph.
    pub written: u64,
    /// Samples that were not written because they are malformed (or the graph refused them).
    pub malformed: u64,
    /// Samples skipped by the topic's rate limit.
    pub rate_skipped: u64,
    /// Why the last malformed sample was refused.
    pub last_error: Option<String>,
}

struct InState {
    channel: Arc<Channel>,
    min_interval_ns: u64,
    last_written_ns: Option<u64>,
    counters: InCounters,
}

/// The In direction's state: the replay bridge (its topic and frame nodes) and one state per configured topic.
pub struct Inbound {
    bridge: Bridge,
    topics: Vec<InState>,
}

impl Inbound {
    /// The inbound side of `inputs`, in their order (a sample is offered with its topic's index).
    pub fn new(inputs: &[InTopic]) -> Inbound {
        let topics = inputs
            .iter()
            .enumerate()
            .map(|(i, input)| {
                let node = input.node.clone().unwrap_or_else(|| input.topic.clone());
                let schema =
                    Schema { id: 1, name: input.type_name.clone(), encoding: String::new(), data: Bytes::new() };
                let channel = Channel {
                    id: u16::try_from(i + 1).unwrap_or(u16::MAX),
                    topic: node.clone(),
                    message_encoding: "cdr".into(),
                    schema: Some(Arc::new(schema)),
                    metadata: Default::default(),
                };
                let min_interval_ns = input.max_rate_hz.map_or(0, |rate| (1e9 / rate) as u64);
                let counters = InCounters { topic: input.topic.clone(), node, ..InCounters::default() };
                InState { channel: Arc::new(channel), min_interval_ns, last_written_ns: None, counters }
            })
            .collect();
        Inbound { bridge: Bridge::new(BridgeOptions::default()), topics }
    }

    /// Counts a received sample of topic `index` and says whether its rate limit lets it through at
    /// `arrival_ns` (a monotonic time); a sample it refuses is counted as skipped.
    pub fn admit(&mut self, index: usize, arrival_ns: u64) -> bool {
        let Some(state) = self.topics.get_mut(index) else { return false };
        state.counters.received += 1;
        let due = state.last_written_ns.is_none_or(|last| arrival_ns.saturating_sub(last) >= state.min_interval_ns);
        if due {
            state.last_written_ns = Some(arrival_ns);
        } else {
            state.counters.rate_skipped += 1;
        }
        due
    }

    /// Writes an admitted sample of topic `index` (its CDR bytes, encapsulation header included) into `replica`
    /// at `now_ns`; returns the deltas to publish. A sample that does not decode is counted and logged.
    pub fn write(&mut self, index: usize, replica: &mut Replica, now_ns: u64, cdr: Bytes) -> Vec<Arc<Delta>> {
        let Some(state) = self.topics.get_mut(index) else { return Vec::new() };
        let sequence = state.counters.received;
        let message = Message {
            channel: Arc::clone(&state.channel),
            sequence: u32::try_from(sequence).unwrap_or(u32::MAX),
            log_time: now_ns,
            publish_time: now_ns,
            data: cdr,
            file_offset: 0,
        };
        let errors_before = self.bridge.stats().error_count();
        let kept_before = self.bridge.stats().first_errors.len();
        let deltas = self.bridge.ingest(replica, now_ns, &message, 0);
        let stats = self.bridge.stats();
        if stats.error_count() > errors_before {
            let reason = match stats.first_errors.get(kept_before) {
                Some(reason) => reason.clone(),
                None => "does not decode (see the first errors above for the reasons of this topic)".to_owned(),
            };
            self.malformed(index, reason);
        } else {
            state_of(&mut self.topics, index).counters.written += 1;
        }
        deltas
    }

    /// Counts a sample of topic `index` that could not even be taken from the DDS reader (another representation,
    /// a sample rustdds could not deserialize), with the reason, and logs it.
    pub fn malformed(&mut self, index: usize, reason: String) {
        let Some(state) = self.topics.get_mut(index) else { return };
        state.counters.malformed += 1;
        let count = state.counters.malformed;
        if count <= LOGGED_MALFORMED || count.is_multiple_of(1000) {
            tracing::warn!("ros2 bridge: malformed sample #{count} on {}: {reason}", state.counters.topic);
        }
        state.counters.last_error = Some(reason.chars().take(REASON_CHARS).collect());
    }

    /// The counters of every input topic, in configuration order.
    pub fn counters(&self) -> Vec<InCounters> {
        self.topics.iter().map(|state| state.counters.clone()).collect()
    }

    /// The replay bridge's own counters (decoded by type, TF transforms refused, deltas).
    pub fn bridge_stats(&self) -> &BridgeStats {
        self.bridge.stats()
    }
}

fn state_of(topics: &mut [InState], index: usize) -> &mut InState {
    &mut topics[index]
}

#[cfg(test)]
mod tests {
    use dsr::{ReplicaId, Value, attrs};
    use replay::ros2::{LaserScan, TransformStamped};

    use super::*;
    use crate::encode::{header_at, laser_scan, tf_message};
    use crate::qos::QosProfile;

    fn input(topic: &str, type_name: &str, max_rate_hz: Option<f64>) -> InTopic {
        InTopic { topic: topic.into(), type_name: type_name.into(), node: None, qos: QosProfile::Sensor, max_rate_hz }
    }

    fn scan(ranges_m: Vec<f32>) -> LaserScan {
        LaserScan {
            header: header_at(3_000_000_000, "laser"),
            angle_min: -0.5,
            angle_max: 0.5,
            angle_increment: 0.5,
            time_increment: 0.0,
            scan_time: 0.1,
            range_min: 0.0,
            range_max: 30.0,
            ranges: ranges_m,
            intensities: vec![],
        }
    }

    #[test]
    fn a_laser_scan_is_written_as_replay_writes_it() {
        let mut replica = Replica::new(ReplicaId(1));
        let mut inbound = Inbound::new(&[input("/scan", "sensor_msgs/msg/LaserScan", None)]);
        assert!(inbound.admit(0, 0));
        let deltas = inbound.write(0, &mut replica, 10, laser_scan(&scan(vec![1.0, 2.0, 3.0])));
        assert!(!deltas.is_empty());
        let node = replica.node_by_name("/scan").expect("the topic's node");
        assert_eq!(node.node_type(), "laser");
        assert_eq!(
            node.attr(attrs::LASER_DISTS.name()),
            Some(&Value::VecF32(dsr::Numbers::from([1000.0f32, 2000.0, 3000.0])))
        );
        assert_eq!(node.attr(attrs::STAMP_NS.name()), Some(&Value::U64(3_000_000_000)));
        assert!(replica.node_by_name("laser").is_some(), "the header's frame becomes the node's parent");
        assert_eq!(inbound.counters()[0].written, 1);
    }

    #[test]
    fn truncated_and_foreign_samples_are_counted_and_leave_the_graph_unchanged() {
        let mut replica = Replica::new(ReplicaId(1));
        let mut inbound = Inbound::new(&[input("/scan", "sensor_msgs/msg/LaserScan", None)]);
        let good = laser_scan(&scan(vec![1.0; 8]));
        for cut in [0, 3, 4, 20, good.len() - 1] {
            assert!(inbound.admit(0, cut as u64));
            assert!(inbound.write(0, &mut replica, 1, good.slice(..cut)).is_empty(), "cut {cut}");
        }
        // Another type's bytes on this topic: an image whose `encoding` string stands where the scan's ranges count
        // is read, so the count runs past the end.
        let image = replay::ros2::Image {
            header: header_at(1, "camera"),
            height: 2,
            width: 2,
            encoding: "rgb8".into(),
            is_bigendian: false,
            step: 6,
            data: Bytes::from(vec![200u8; 12]),
        };
        inbound.admit(0, 100);
        assert!(inbound.write(0, &mut replica, 1, crate::encode::image(&image)).is_empty());
        assert_eq!(replica.node_count(), 0);
        let counters = &inbound.counters()[0];
        assert_eq!((counters.received, counters.malformed, counters.written), (6, 6, 0));
        assert!(counters.last_error.as_deref().unwrap().contains("sensor_msgs/msg/LaserScan"), "{counters:?}");
    }

    #[test]
    fn the_rate_limit_skips_samples_closer_than_its_interval() {
        let mut inbound = Inbound::new(&[input("/scan", "sensor_msgs/msg/LaserScan", Some(10.0))]);
        let admitted: Vec<bool> =
            [0, 50_000_000, 99_999_999, 100_000_000, 150_000_000, 250_000_000].map(|t| inbound.admit(0, t)).into();
        assert_eq!(admitted, [true, false, false, true, false, true]);
        assert_eq!(inbound.counters()[0].rate_skipped, 3);
    }

    #[test]
    fn a_tf_message_becomes_rt_edges_and_the_target_node_is_the_one_configured() {
        let mut replica = Replica::new(ReplicaId(1));
        let mut scan_topic = input("/scan", "sensor_msgs/msg/LaserScan", None);
        scan_topic.node = Some("front_laser".into());
        let mut inbound = Inbound::new(&[input("/tf", "tf2_msgs/msg/TFMessage", None), scan_topic]);
        let transform = TransformStamped {
            header: header_at(1, "world"),
            child_frame_id: "base".into(),
            translation: [1.0, 2.0, 3.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        inbound.admit(0, 0);
        inbound.write(0, &mut replica, 1, tf_message(&[transform]));
        inbound.admit(1, 0);
        inbound.write(1, &mut replica, 2, laser_scan(&scan(vec![1.0])));
        let (world, base) = (replica.node_by_name("world").unwrap().id(), replica.node_by_name("base").unwrap().id());
        let pose = replica.transform(base, world).unwrap();
        assert!((pose.translation.vector - nalgebra::Vector3::new(1000.0, 2000.0, 3000.0)).norm() < 1e-3);
        assert!(replica.node_by_name("front_laser").is_some());
        assert_eq!(inbound.counters()[1].node, "front_laser");
    }
}
