//! Tests of the MCAP reader: a sample of the conformance suite against its expected record streams, the malformed
//! files of the `mcap` crate, the bundled real logs (counts per topic from the manifest), and damaged copies of a
//! real log (truncations and bit flips: errors that say where, never a panic; recovery keeps a prefix).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use bytes::Bytes;
use proptest::prelude::*;
use replay::log::{DamageKind, Log, LogError, ReadOptions};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn logs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs")
}

/// (channel id, sequence, log time, publish time, data) of the JSON's message records, stably sorted by log time.
fn expected_messages(json: &Path) -> Vec<(u16, u32, u64, u64, Vec<u8>)> {
    let value: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    let mut out = Vec::new();
    for record in value["records"].as_array().unwrap() {
        if record["type"] != "Message" {
            continue;
        }
        let fields: BTreeMap<&str, &serde_json::Value> =
            record["fields"].as_array().unwrap().iter().map(|pair| (pair[0].as_str().unwrap(), &pair[1])).collect();
        let int = |name: &str| fields[name].as_str().unwrap().parse::<u64>().unwrap();
        let data = fields["data"].as_array().unwrap().iter().map(|b| b.as_str().unwrap().parse().unwrap()).collect();
        out.push((int("channel_id") as u16, int("sequence") as u32, int("log_time"), int("publish_time"), data));
    }
    out.sort_by_key(|message| message.2);
    out
}

#[test]
fn conformance_sample_gives_the_expected_messages() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(fixtures().join("conformance"))
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "mcap"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 52);
    let mut total = 0;
    for file in &files {
        let log = Log::open(file, ReadOptions::default()).unwrap_or_else(|error| panic!("{error}"));
        let got: Vec<_> = log
            .messages
            .iter()
            .map(|m| (m.channel.id, m.sequence, m.log_time, m.publish_time, m.data.to_vec()))
            .collect();
        assert_eq!(got, expected_messages(&file.with_extension("json")), "{}", file.display());
        total += got.len();
    }
    assert!(total > 100, "the sample holds messages: {total}");
}

#[test]
fn ros1_log_reads_with_its_counts() {
    let log = Log::open(fixtures().join("compressed.mcap"), ReadOptions::default()).unwrap();
    assert_eq!(log.profile, "ros1");
    let mut by_type = BTreeMap::new();
    for message in &log.messages {
        *by_type.entry(message.channel.type_name().to_owned()).or_insert(0) += 1;
    }
    assert_eq!(by_type["tf2_msgs/TFMessage"], 774);
    assert_eq!(by_type["diagnostic_msgs/DiagnosticArray"], 52);
    assert!(log.messages.windows(2).all(|pair| pair[0].log_time <= pair[1].log_time));
}

#[test]
fn chunk_with_undefined_channel_is_an_error_that_says_where() {
    let path = fixtures().join("zstd_chunk_with_padding.mcap");
    let error = Log::open(&path, ReadOptions::default()).unwrap_err();
    let LogError::Damaged { damage, .. } = &error else { panic!("{error}") };
    assert_eq!(damage.kind, DamageKind::UnknownChannel(0));
    assert_eq!(damage.record, "message");
    assert!(damage.chunk.is_some(), "inside a chunk: {error}");
    let text = error.to_string();
    assert!(text.contains("undefined channel 0") && text.contains("of the chunk at file byte"), "{text}");
    // The chunk itself decompressed (the padding after the zstd frame is skipped): the damage is its first message.
    assert_eq!(damage.offset, 0, "{text}");
    let recovered = Log::open(&path, ReadOptions { recover: true, ..ReadOptions::default() }).unwrap();
    assert!(recovered.messages.is_empty());
    assert_eq!(recovered.damage.as_ref(), Some(&**damage));
    assert!(recovered.unread_bytes > 0);
}

#[test]
fn unclosed_chunk_is_an_error_after_the_header() {
    let path = fixtures().join("chunk_not_closed.mcap");
    let error = Log::open(&path, ReadOptions::default()).unwrap_err();
    let LogError::Damaged { damage, .. } = &error else { panic!("{error}") };
    assert_eq!(damage.record, "chunk");
    assert!(matches!(damage.kind, DamageKind::Truncated { field: "record body", .. }), "{error}");
    assert!(damage.offset > 8, "after the header: {error}");
    let recovered = Log::open(&path, ReadOptions { recover: true, ..ReadOptions::default() }).unwrap();
    assert_eq!(recovered.profile, "", "the header was read");
    assert!(recovered.messages.is_empty());
}

#[test]
fn not_an_mcap_file() {
    let error = Log::from_bytes("x", Bytes::from_static(b"hello, world"), ReadOptions::default()).unwrap_err();
    let expected = "x: magic record at byte 0: bad magic bytes (not an MCAP file, a ROS 1 bag v2.0 or a rosbag2 bag, or a damaged one)";
    assert_eq!(error.to_string(), expected);
    let error = Log::open("/nonexistent/file.mcap", ReadOptions::default()).unwrap_err();
    assert_eq!(error.to_string(), "cannot open /nonexistent/file.mcap");
    let cause = std::error::Error::source(&error).expect("the operating system's error is the source");
    assert!(cause.to_string().contains("No such file"), "{cause}");
}

/// Counts per topic of the bundled logs, from `datasets/logs/manifest.json` (written by the Python reader).
#[test]
fn bundled_logs_match_the_manifest() {
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(logs().join("manifest.json")).unwrap()).unwrap();
    for file in manifest["files"].as_array().unwrap() {
        let name = file["file"].as_str().unwrap();
        let log = Log::open(logs().join(name), ReadOptions::default()).unwrap();
        assert_eq!(log.profile, "ros2");
        let mut counts: BTreeMap<String, (String, u64)> = BTreeMap::new();
        for message in &log.messages {
            let entry = counts
                .entry(message.channel.topic.clone())
                .or_insert_with(|| (message.channel.type_name().to_owned(), 0));
            entry.1 += 1;
        }
        let expected: BTreeMap<String, (String, u64)> = file["topics"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| {
                let topic = t["topic"].as_str().unwrap().to_owned();
                (topic, (t["type"].as_str().unwrap().to_owned(), t["count"].as_u64().unwrap()))
            })
            .collect();
        assert_eq!(counts, expected, "{name}");
        let (start, end) = log.time_range().unwrap();
        assert_eq!((start, end), (file["log_start_ns"].as_u64().unwrap(), file["log_end_ns"].as_u64().unwrap()));
    }
}

fn husky() -> Bytes {
    Bytes::from(std::fs::read(logs().join("husky_gps_imu_odom_robot_localization_test1.mcap")).unwrap())
}

#[test]
fn truncated_real_log_recovers_a_prefix() {
    let bytes = husky();
    let full = Log::from_bytes("husky", bytes.clone(), ReadOptions::default()).unwrap();
    let cut = bytes.slice(..bytes.len() / 2);
    let error = Log::from_bytes("husky", cut.clone(), ReadOptions::default()).unwrap_err();
    let LogError::Damaged { damage, .. } = &error else { panic!("{error}") };
    assert!(matches!(damage.kind, DamageKind::Truncated { .. }), "{error}");
    assert_eq!(damage.record, "chunk", "{error}");
    let recovered = Log::from_bytes("husky", cut, ReadOptions { recover: true, ..ReadOptions::default() }).unwrap();
    assert!(!recovered.messages.is_empty() && recovered.messages.len() < full.messages.len());
    assert_eq!(recovered.unread_bytes, bytes.len() as u64 / 2 - damage.offset);
    // What was recovered is exactly the first messages of the file (its chunks are in time order).
    for (got, want) in recovered.messages.iter().zip(&full.messages) {
        assert_eq!((got.log_time, &got.data), (want.log_time, &want.data));
    }
}

#[test]
fn flipped_bit_in_a_compressed_chunk_is_caught() {
    // The SICK cut was written with chunk CRCs (lz4 chunks).
    let bytes = std::fs::read(logs().join("sick_tim7xx_scan_10s.mcap")).unwrap();
    let mut damaged = bytes.clone();
    // A byte in the middle of the first chunk's compressed records.
    damaged[20_000] ^= 0x10;
    let Err(error) = Log::from_bytes("sick", Bytes::from(damaged), ReadOptions::default()) else {
        panic!("a flipped bit went unnoticed")
    };
    let LogError::Damaged { damage, .. } = &error else { panic!("{error}") };
    assert_eq!(damage.record, "chunk", "{error}");
    assert!(
        matches!(damage.kind, DamageKind::Crc { .. } | DamageKind::Decompress { .. } | DamageKind::Size { .. }),
        "{error}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Any truncation or bit flip of a real log gives a log or an error, never a panic; with recovery, never an
    /// error other than an unreadable file, and never more messages than the original.
    #[test]
    fn damaged_real_log_never_panics(cut in 0.0f64..1.0, flips in proptest::collection::vec((0.0f64..1.0, 0u8..8), 0..4)) {
        let bytes = husky();
        let total = Log::from_bytes("husky", bytes.clone(), ReadOptions::default()).unwrap().messages.len();
        let mut damaged = bytes.to_vec();
        for (at, bit) in flips {
            let index = ((damaged.len() - 1) as f64 * at) as usize;
            damaged[index] ^= 1 << bit;
        }
        damaged.truncate(8 + ((damaged.len() - 8) as f64 * cut) as usize);
        let damaged = Bytes::from(damaged);
        let _ = Log::from_bytes("husky", damaged.clone(), ReadOptions::default());
        let recovered = Log::from_bytes("husky", damaged, ReadOptions { recover: true, ..ReadOptions::default() });
        let recovered = recovered.map_err(|error| error.to_string());
        prop_assert!(recovered.is_ok(), "{:?}", recovered.err());
        prop_assert!(recovered.unwrap().messages.len() <= total);
    }

    /// Arbitrary bytes after the magic never panic.
    #[test]
    fn arbitrary_records_never_panic(body in proptest::collection::vec(any::<u8>(), 0..512)) {
        let mut bytes = replay::log::MAGIC.to_vec();
        bytes.extend(body);
        let _ = Log::from_bytes("random", Bytes::from(bytes), ReadOptions::default());
    }
}
