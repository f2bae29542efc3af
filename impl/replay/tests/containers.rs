//! Tests of the containers and encodings beside ROS 2 MCAP, on the logs of `datasets/logs/containers/` (the same
//! real recordings converted by `rosbags`, see its README): every container of a log reads the same messages and
//! gives the same graph and counts; ROS 1 and CDR payloads decode to the same values; messages of types the bridge has
//! no decoder for are decoded from the definitions the files carry; damaged bags, rosbag2 directories and
//! definitions give errors that say where, and recovery keeps what is readable.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use bytes::Bytes;
use dsr::{Replica, ReplicaId, Value};
use replay::log::{Container, DamageKind, Log, LogError, ReadOptions};
use replay::ros2::{self, Encoding};
use replay::{Bridge, BridgeOptions, BridgeStats};

fn containers() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs/containers")
}

fn open(name: &str) -> Log {
    Log::open(containers().join(name), ReadOptions::default()).unwrap_or_else(|error| panic!("{error}"))
}

const RECOVER: ReadOptions = ReadOptions { recover: true, check_crc: true, max_chunk_bytes: 1 << 30 };

/// The Husky log (10 s) in every container, with the container each must be detected as.
const HUSKY: &[(&str, Container)] = &[
    ("husky_10s.mcap", Container::Mcap),
    ("husky_10s.bag", Container::Ros1Bag),
    ("husky_10s_bz2.bag", Container::Ros1Bag),
    ("husky_10s_lz4.bag", Container::Ros1Bag),
    ("husky_10s_ros1.mcap", Container::Mcap),
    ("husky_10s_sqlite3", Container::Rosbag2Sqlite3),
    ("husky_10s_rosbag2_mcap", Container::Rosbag2Mcap),
];

/// The SICK log (1 s: LaserScan and PointCloud2) in its containers.
const SICK: &[(&str, Container)] = &[
    ("sick_1s.mcap", Container::Mcap),
    ("sick_1s_lz4.bag", Container::Ros1Bag),
    ("sick_1s_ros1.mcap", Container::Mcap),
    ("sick_1s_sqlite3", Container::Rosbag2Sqlite3),
];

/// The custom-message log (a vendor radar type and DiagnosticArray) in its containers.
const CUSTOM: &[(&str, Container)] = &[
    ("custom_radar_diag_rosbag2_mcap", Container::Rosbag2Mcap),
    ("custom_radar_diag.bag", Container::Ros1Bag),
    ("custom_radar_diag_ros1.mcap", Container::Mcap),
    ("custom_radar_diag_sqlite3", Container::Rosbag2Sqlite3),
];

/// Replays a log into a fresh bridge replica: the bridge's counters and the visible graph's digest.
fn replay_log(log: &Log, options: BridgeOptions) -> (BridgeStats, String, Bridge, Replica) {
    let mut bridge = Bridge::new(options);
    let mut replica = Replica::with_dictionary(ReplicaId(1), replay::bridge::dictionary().unwrap());
    for message in &log.messages {
        bridge.ingest(&mut replica, message.log_time, message, 0);
    }
    (bridge.stats().clone(), replica.digest().to_string(), bridge, replica)
}

/// (topic, log time) of every message, in log order.
fn timeline(log: &Log) -> Vec<(String, u64)> {
    log.messages.iter().map(|m| (m.channel.topic.clone(), m.log_time)).collect()
}

#[test]
fn every_container_of_a_log_reads_the_same_messages() {
    for set in [HUSKY, SICK, CUSTOM] {
        let reference = open(set[0].0);
        for &(name, container) in set {
            let log = open(name);
            assert_eq!(log.container, container, "{name}");
            assert_eq!(timeline(&log), timeline(&reference), "{name}");
        }
    }
    assert_eq!(open("husky_10s_bz2.bag").messages.len(), 426);
}

#[test]
fn every_container_of_a_log_gives_the_same_graph_and_counts() {
    for set in [HUSKY, SICK, CUSTOM] {
        let (reference, digest, ..) = replay_log(&open(set[0].0), BridgeOptions::default());
        assert_eq!(reference.error_count(), 0, "{:?}", reference.first_errors);
        assert!(reference.unknown.is_empty(), "{:?}", reference.unknown);
        for &(name, _) in &set[1..] {
            let (stats, other_digest, ..) = replay_log(&open(name), BridgeOptions::default());
            assert_eq!(stats.error_count(), 0, "{name}: {:?}", stats.first_errors);
            assert_eq!((&stats.decoded, &stats.described), (&reference.decoded, &reference.described), "{name}");
            assert_eq!(stats.deltas, reference.deltas, "{name}");
            assert_eq!(other_digest, digest, "{name}: the same visible graph");
        }
    }
}

#[test]
fn ros1_and_cdr_payloads_decode_to_the_same_messages() {
    for (cdr_name, ros1_name) in [("husky_10s.mcap", "husky_10s_lz4.bag"), ("sick_1s.mcap", "sick_1s_ros1.mcap")] {
        let (cdr, ros1) = (open(cdr_name), open(ros1_name));
        let mut decoded = 0;
        for (a, b) in cdr.messages.iter().zip(&ros1.messages) {
            assert_ne!(a.channel.type_name(), b.channel.type_name(), "pkg/msg/Type beside pkg/Type");
            let left = ros2::decode_as(a.channel.type_name(), Encoding::Cdr, &a.data).unwrap().unwrap();
            let right = ros2::decode_as(b.channel.type_name(), Encoding::Ros1, &b.data).unwrap().unwrap();
            assert_eq!(left, right, "{} at {}", a.channel.topic, a.log_time);
            decoded += 1;
        }
        assert_eq!(decoded, cdr.messages.len());
    }
}

#[test]
fn ros1_mcap_fixture_decodes_tf_and_diagnostics() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/compressed.mcap");
    let log = Log::open(path, ReadOptions::default()).unwrap();
    let (stats, ..) = replay_log(&log, BridgeOptions::default());
    assert_eq!(stats.decoded["tf2_msgs/msg/TFMessage"], 774, "{:?}", stats.first_errors);
    assert_eq!(stats.described["diagnostic_msgs/msg/DiagnosticArray"], 52, "{:?}", stats.first_errors);
    assert_eq!(stats.error_count(), 0, "{:?}", stats.first_errors);
}

#[test]
fn custom_messages_reach_the_graph_as_flattened_attributes() {
    for &(name, _) in CUSTOM {
        let (stats, _, bridge, replica) = replay_log(&open(name), BridgeOptions::default());
        let expected = BTreeMap::from([
            ("acme_radar_msgs/msg/RadarScan".to_owned(), 10),
            ("diagnostic_msgs/msg/DiagnosticArray".to_owned(), 10),
        ]);
        assert_eq!(stats.described, expected, "{name}: {:?}", stats.first_errors);
        let radar = replica.node(bridge.topic_node("/radar/scan").unwrap()).unwrap();
        let attr = |key: &str| radar.attr(key).cloned().unwrap_or_else(|| panic!("{name}: no {key}"));
        assert_eq!(attr("RadarScan.scan_id"), Value::U32(1009), "{name}");
        assert_eq!(attr("RadarScan.mode"), Value::I32(1));
        assert_eq!(attr("RadarScan.valid"), Value::Bool(false));
        assert_eq!(attr("RadarScan.targets.2.label"), Value::String("target-2".into()));
        assert_eq!(attr("RadarScan.targets.2.range"), Value::F32(21.0));
        assert_eq!(attr("RadarScan.targets.1.rcs"), Value::I32(-4));
        assert_eq!(attr("RadarScan.sensor_position"), Value::VecF32(vec![0.5, 0.0, 1.25].into()));
        assert_eq!(attr("RadarScan.noise_floor"), Value::VecF32(vec![-81.0, -91.0, -92.5, -93.0].into()));
        let frame: Vec<u8> = (0..16).map(|k| (9 * 7 + k) as u8).collect();
        assert_eq!(attr("RadarScan.raw_frame"), Value::Bytes(Bytes::from(frame)));
        assert_eq!(attr("stamp_ns"), Value::U64(1_700_000_000_900_000_000));
        assert!(radar.attr("RadarScan.header.seq").is_none() && radar.attr("RadarScan.header.stamp").is_none());
        let parent = replica.rt_parent_edge(radar.id()).unwrap().expect("hangs under its frame");
        assert_eq!(replica.node(parent.from()).unwrap().name(), "radar_link");
        let diagnostics = replica.node(bridge.topic_node("/diagnostics").unwrap()).unwrap();
        let value = diagnostics.attr("DiagnosticArray.status.1.values.0.value").cloned();
        assert_eq!(value, Some(Value::String("49.1".into())), "{name}");
        assert_eq!(diagnostics.attr("DiagnosticArray.status.0.level").cloned(), Some(Value::I32(0)));
    }
}

#[test]
fn opaque_keeps_raw_bytes_instead_of_decoding() {
    let log = open("custom_radar_diag.bag");
    let (stats, _, bridge, replica) = replay_log(&log, BridgeOptions { opaque: true, ..BridgeOptions::default() });
    assert!(stats.described.is_empty());
    assert_eq!(stats.unknown["acme_radar_msgs/msg/RadarScan"], 10);
    assert_eq!(stats.opaque, 20);
    let radar = replica.node(bridge.topic_node("/radar/scan").unwrap()).unwrap();
    let last = log.messages.iter().rfind(|m| m.channel.topic == "/radar/scan").unwrap();
    assert_eq!(radar.attr("opaque_payload").cloned(), Some(Value::Bytes(last.data.clone())));
}

#[test]
fn container_is_detected_from_content_not_name() {
    let scratch = scratch("detected");
    let dir = scratch.path();
    let renamed = dir.join("looks_like.mcap");
    std::fs::copy(containers().join("husky_10s_lz4.bag"), &renamed).unwrap();
    let log = Log::open(&renamed, ReadOptions::default()).unwrap();
    assert_eq!((log.container, log.messages.len()), (Container::Ros1Bag, 426));
    let lone_db = dir.join("recording.bin");
    std::fs::copy(containers().join("husky_10s_sqlite3/husky_10s_sqlite3.db3"), &lone_db).unwrap();
    let log = Log::open(&lone_db, ReadOptions::default()).unwrap();
    assert_eq!((log.container, log.messages.len()), (Container::Rosbag2Sqlite3, 426));
}

fn bag_bytes(name: &str) -> Vec<u8> {
    std::fs::read(containers().join(name)).unwrap()
}

#[test]
fn truncated_bag_names_the_record_and_recovery_keeps_whole_chunks() {
    let bytes = bag_bytes("husky_10s_bz2.bag");
    let cut = Bytes::from(bytes[..bytes.len() * 6 / 10].to_vec());
    let error = Log::from_bytes("cut.bag", cut.clone(), ReadOptions::default()).unwrap_err();
    let LogError::Damaged { damage, .. } = &error else { panic!("{error}") };
    assert!(matches!(damage.kind, DamageKind::Truncated { .. }), "{error}");
    assert_eq!(damage.record, "chunk", "{error}");
    assert!(error.to_string().starts_with("cut.bag: chunk record at byte "), "{error}");
    let recovered = Log::from_bytes("cut.bag", cut, RECOVER).unwrap();
    assert!(recovered.damage.is_some() && recovered.unread_bytes > 0);
    let n = recovered.messages.len();
    assert!(n > 100 && n < 426, "{n} messages from the whole chunks before the cut");
    let whole = open("husky_10s_bz2.bag");
    assert_eq!(timeline(&recovered), timeline(&whole)[..n].to_vec(), "a prefix of the log");
}

#[test]
fn bag_without_index_is_an_error_and_recovery_reads_every_chunk() {
    let mut bytes = bag_bytes("husky_10s_lz4.bag");
    let at = bytes.windows(10).position(|w| w == b"index_pos=").unwrap() + 10;
    bytes[at..at + 8].copy_from_slice(&0u64.to_le_bytes());
    let error = Log::from_bytes("open.bag", Bytes::from(bytes.clone()), ReadOptions::default()).unwrap_err();
    let LogError::Damaged { damage, .. } = &error else { panic!("{error}") };
    assert!(matches!(damage.kind, DamageKind::NoIndex(_)), "{error}");
    assert_eq!((damage.record, damage.offset), ("bag header", 13), "{error}");
    assert!(error.to_string().contains("index_pos is 0"), "{error}");
    let recovered = Log::from_bytes("open.bag", Bytes::from(bytes), RECOVER).unwrap();
    assert_eq!(recovered.messages.len(), 426);
    // Cut just before the index section: every chunk is whole, the index is gone.
    let bytes = bag_bytes("husky_10s_lz4.bag");
    let index_pos = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    let error =
        Log::from_bytes("cut.bag", Bytes::from(bytes[..index_pos].to_vec()), ReadOptions::default()).unwrap_err();
    assert!(error.to_string().contains("past the end of the file"), "{error}");
}

#[test]
fn damaged_bags_never_panic() {
    for name in ["sick_1s_lz4.bag", "husky_10s_bz2.bag"] {
        let bytes = bag_bytes(name);
        for step in 0..48 {
            let mut damaged = bytes.clone();
            let at = (step * 7919 * 31) % damaged.len();
            damaged[at] ^= 1 << (step % 8);
            let cut = damaged.len() - (step * 997) % 4096;
            let _ = Log::from_bytes("x.bag", Bytes::from(damaged[..cut].to_vec()), RECOVER);
        }
    }
}

#[test]
fn every_prefix_of_a_described_payload_is_an_error_not_a_panic() {
    for name in ["custom_radar_diag.bag", "custom_radar_diag_rosbag2_mcap"] {
        let log = open(name);
        for message in &log.messages {
            let schema = message.channel.schema.as_ref().unwrap();
            let text = String::from_utf8_lossy(&schema.data);
            let definitions = replay::msgdef::Definitions::parse(&schema.name, &text).unwrap();
            let encoding = Encoding::from_message_encoding(&message.channel.message_encoding).unwrap();
            let limits = replay::generic::Limits::default();
            assert!(replay::generic::decode(&definitions, encoding, &message.data, limits).is_ok());
            for cut in 0..message.data.len() {
                let prefix = message.data.slice(..cut);
                assert!(replay::generic::decode(&definitions, encoding, &prefix, limits).is_err(), "{name} {cut}");
            }
        }
    }
}

/// An empty directory for `test`, removed when the returned guard is dropped (at the end of the test, pass or fail).
fn scratch(test: &str) -> tempfile::TempDir {
    tempfile::Builder::new().prefix(&format!("cortex-replay-containers-{test}-")).tempdir().unwrap()
}

/// A copy of a rosbag2 directory in a scratch directory of `test`: the guard and the copy's path.
fn copy_dir(name: &str, test: &str) -> (tempfile::TempDir, PathBuf) {
    let scratch = scratch(test);
    let dir = scratch.path().join(name);
    std::fs::create_dir(&dir).unwrap();
    for entry in std::fs::read_dir(containers().join(name)).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
    }
    (scratch, dir)
}

#[test]
fn corrupt_sqlite_file_names_the_table() {
    let (_scratch, dir) = copy_dir("husky_10s_sqlite3", "corrupt");
    let db = dir.join("husky_10s_sqlite3.db3");
    let mut bytes = std::fs::read(&db).unwrap();
    bytes[16..4096].fill(0xA5);
    std::fs::write(&db, &bytes).unwrap();
    let error = Log::open(&dir, ReadOptions::default()).unwrap_err();
    let LogError::Damaged { file, damage } = &error else { panic!("{error}") };
    assert!(file.ends_with("husky_10s_sqlite3.db3"), "{error}");
    assert!(damage.table.is_some(), "{error}");
    assert!(error.to_string().contains("table `sqlite_master`: sqlite: file is not a database"), "{error}");
}

#[test]
fn corrupt_sqlite_page_is_an_error_at_its_row_and_recovery_keeps_the_rows_before() {
    let (_scratch, dir) = copy_dir("husky_10s_sqlite3", "page");
    let db = dir.join("husky_10s_sqlite3.db3");
    let mut bytes = std::fs::read(&db).unwrap();
    bytes[30 * 4096..31 * 4096].fill(0xA5);
    std::fs::write(&db, &bytes).unwrap();
    let error = Log::open(&dir, ReadOptions::default()).unwrap_err();
    let LogError::Damaged { damage, .. } = &error else { panic!("{error}") };
    assert_eq!((damage.table, damage.record), (Some("messages"), "message"), "{error}");
    assert!(error.to_string().contains(" of table `messages`: sqlite: "), "{error}");
    let recovered = Log::open(&dir, RECOVER).unwrap();
    let n = recovered.messages.len();
    assert!(n > 100 && n < 426, "{n}");
    assert_eq!(recovered.damage.as_ref().unwrap().offset, n as u64 + 1, "the first row not read");
    assert_eq!(timeline(&recovered), timeline(&open("husky_10s_sqlite3"))[..n].to_vec());
}

#[test]
fn rosbag2_directory_without_metadata_says_so() {
    let (_scratch, dir) = copy_dir("husky_10s_rosbag2_mcap", "no-metadata");
    std::fs::remove_file(dir.join("metadata.yaml")).unwrap();
    let error = Log::open(&dir, ReadOptions::default()).unwrap_err();
    assert!(error.to_string().contains("needs its metadata.yaml"), "{error}");
}

#[test]
fn definition_that_does_not_parse_is_an_error_for_its_topic_only() {
    let mut bytes = bag_bytes("custom_radar_diag.bag");
    let needle = b"float64[3] sensor_position";
    let mut count = 0;
    while let Some(at) = bytes.windows(needle.len()).position(|w| w == needle) {
        bytes[at..at + needle.len()].copy_from_slice(b"float64[?] sensor_position");
        count += 1;
    }
    assert!(count >= 1);
    let log = Log::from_bytes("custom.bag", Bytes::from(bytes), ReadOptions::default()).unwrap();
    let (stats, ..) = replay_log(&log, BridgeOptions::default());
    assert_eq!(stats.errors["/radar/scan"], 10);
    assert_eq!(stats.described["diagnostic_msgs/msg/DiagnosticArray"], 10);
    let first = &stats.first_errors[0];
    assert!(first.contains("definition of acme_radar_msgs/RadarScan: line "), "{first}");
    assert!(first.contains("`?` is not an array length"), "{first}");
}

#[test]
fn humble_sqlite_without_definitions_reads_and_counts_custom_types_as_unknown() {
    let (_scratch, dir) = copy_dir("custom_radar_diag_sqlite3", "humble");
    let db = rusqlite::Connection::open(dir.join("custom_radar_diag_sqlite3.db3")).unwrap();
    db.execute_batch("DROP TABLE message_definitions").unwrap();
    drop(db);
    let log = Log::open(&dir, ReadOptions::default()).unwrap();
    assert_eq!(log.messages.len(), 20);
    let (stats, ..) = replay_log(&log, BridgeOptions::default());
    assert!(stats.described.is_empty());
    assert_eq!(stats.unknown["acme_radar_msgs/msg/RadarScan"], 10);
}
