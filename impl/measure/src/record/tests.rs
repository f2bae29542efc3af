//! Tests of the recordings: files that the `mcap` crate's reader accepts, messages that validate against their
//! channels' schemas, runs recorded from their results and from a live replay.

use std::cell::Cell;
use std::io::Cursor;

use bytes::Bytes;
use dsr::{Delta, Replica, ReplicaId};
use replay::inproc::InProcNetwork;
use replay::log::{Log, ReadOptions};
use replay::{Bridge, BridgeOptions, Pacer, Rate};

use super::runs::slug;
use super::*;
use crate::clock::MonoClock;
use crate::run::{self, RunConfig};
use crate::workload;

/// Whether `value` has the structure `schema` describes: types, enums, required and unexpected keys, nested
/// objects and arrays (the subset of JSON Schema our schemas use).
fn conforms(value: &Json, schema: &Json, at: &str) -> Result<(), String> {
    let type_ok = |name: &str| match name {
        "object" => value.is_object(),
        "array" => value.is_array(),
        "string" => value.is_string(),
        "integer" => value.is_u64() || value.is_i64(),
        "number" => value.is_number(),
        "boolean" => value.is_boolean(),
        "null" => value.is_null(),
        other => panic!("unknown type {other} in a schema"),
    };
    let types: Vec<&str> = match &schema["type"] {
        Json::String(t) => vec![t.as_str()],
        Json::Array(ts) => ts.iter().filter_map(Json::as_str).collect(),
        other => return Err(format!("{at}: schema without a type: {other}")),
    };
    if !types.iter().any(|t| type_ok(t)) {
        return Err(format!("{at}: {value} is not of type {types:?}"));
    }
    if let Some(min) = schema["minimum"].as_f64()
        && value.as_f64().is_some_and(|v| v < min)
    {
        return Err(format!("{at}: {value} below {min}"));
    }
    if let Some(allowed) = schema["enum"].as_array()
        && !allowed.contains(value)
    {
        return Err(format!("{at}: {value} not in {allowed:?}"));
    }
    if let (Some(object), Some(properties)) = (value.as_object(), schema["properties"].as_object()) {
        for key in schema["required"].as_array().into_iter().flatten() {
            let key = key.as_str().unwrap();
            if !object.contains_key(key) {
                return Err(format!("{at}: required `{key}` missing"));
            }
        }
        for (key, item) in object {
            match properties.get(key) {
                Some(property) => conforms(item, property, &format!("{at}.{key}"))?,
                None if schema["additionalProperties"] == false => {
                    return Err(format!("{at}: `{key}` is not in the schema"));
                }
                None => {}
            }
        }
    } else if let (Some(object), Some(each)) = (value.as_object(), schema["additionalProperties"].as_object()) {
        for (key, item) in object {
            conforms(item, &Json::Object(each.clone()), &format!("{at}.{key}"))?;
        }
    }
    if let (Some(items), Some(each)) = (value.as_array(), schema.get("items")) {
        for (i, item) in items.iter().enumerate() {
            conforms(item, each, &format!("{at}[{i}]"))?;
        }
    }
    Ok(())
}

/// Reads `bytes` with both readers and checks what every recording must be; returns the messages per topic as
/// the project's reader sees them (payloads as JSON where the channel is JSON).
fn check_recording(bytes: &[u8]) -> BTreeMap<String, Vec<(u64, Bytes)>> {
    // The `mcap` crate: an indexed file whose summary agrees with its messages.
    let summary = mcap::Summary::read(bytes).unwrap().expect("a summary section");
    let stats = summary.stats.clone().expect("statistics");
    assert!(!summary.chunk_indexes.is_empty(), "chunk indexes");
    assert!(summary.chunk_indexes.iter().all(|c| !c.message_index_offsets.is_empty()), "no chunk without messages");
    assert_eq!(summary.metadata_indexes.len(), 1);
    let metadata = mcap::read::metadata(bytes, &summary.metadata_indexes[0]).unwrap();
    assert_eq!(metadata.name, RUN_METADATA);
    assert!(metadata.metadata.contains_key("commit") && metadata.metadata.contains_key("clock"));
    let mut last = 0;
    let mut per_channel: BTreeMap<u16, u64> = BTreeMap::new();
    for message in mcap::MessageStream::new(bytes).unwrap() {
        let message = message.unwrap();
        assert!(message.log_time >= last, "log times never decrease");
        last = message.log_time;
        *per_channel.entry(message.channel.id).or_insert(0) += 1;
        if message.channel.message_encoding == "json" {
            let schema = message.channel.schema.as_ref().expect("a JSON channel has a schema");
            assert_eq!(schema.encoding, "jsonschema");
            let schema: Json = serde_json::from_slice(&schema.data).expect("the schema is JSON");
            let value: Json = serde_json::from_slice(&message.data).expect("the message is JSON");
            conforms(&value, &schema, &message.channel.topic).unwrap();
        } else {
            assert_eq!(message.channel.topic, DELTA_TOPIC);
            assert_eq!(message.channel.message_encoding, DELTA_MESSAGE_ENCODING);
        }
    }
    assert_eq!(per_channel, stats.channel_message_counts);
    assert_eq!(stats.message_count, per_channel.values().sum::<u64>());
    assert_eq!(stats.message_end_time, last);

    // The project's own reader: the same channels and messages.
    let log = Log::from_bytes("recording", Bytes::copy_from_slice(bytes), ReadOptions::default()).unwrap();
    assert!(log.damage.is_none());
    assert_eq!(log.messages.len() as u64, stats.message_count);
    for metric in Metric::ALL {
        let channel = log.channels.values().find(|c| c.topic == metric.topic()).expect("every metric channel");
        assert_eq!((channel.type_name(), channel.message_encoding.as_str()), (metric.schema_name(), "json"));
        let schema: Json = serde_json::from_slice(&channel.schema.as_ref().unwrap().data).unwrap();
        assert_eq!(schema, metric.schema());
        assert_eq!(schema["type"], "object");
        assert_eq!(schema["required"].as_array().unwrap().len(), schema["properties"].as_object().unwrap().len());
    }
    let mut topics: BTreeMap<String, Vec<(u64, Bytes)>> = BTreeMap::new();
    for message in &log.messages {
        topics.entry(message.channel.topic.clone()).or_default().push((message.log_time, message.data.clone()));
    }
    topics
}

fn json_of<T: serde::de::DeserializeOwned>(messages: &[(u64, Bytes)]) -> Vec<T> {
    messages.iter().map(|(_, data)| serde_json::from_slice(data).unwrap()).collect()
}

#[test]
fn a_measured_run_records_every_latency_and_reads_back_with_both_readers() {
    let workload = workload::synthetic(300, 2000.0, 40, 3).unwrap();
    let result = run::run(&workload, &RunConfig { agents: 4, ..RunConfig::default() }).unwrap();
    assert_eq!(result.timeline.writes().len(), 41);
    let mut recorder = RunRecorder::new(
        Cursor::new(Vec::new()),
        BTreeMap::from([("commit".to_owned(), "test".to_owned()), ("clock".to_owned(), "test".to_owned())]),
    )
    .unwrap();
    record_result(&mut recorder, &result).unwrap();
    let (out, counts) = recorder.finish().unwrap();
    let topics = check_recording(out.get_ref());

    let latencies: Vec<WriteLatency> = json_of(&topics["/metrics/latency"]);
    assert_eq!(latencies.len(), 41 * 3);
    assert_eq!(counts[Metric::Latency.topic()], 41 * 3);
    for sample in &latencies {
        assert_eq!(sample.latency_ns, sample.apply_ns - sample.publish_ns);
        assert!((1..=3).contains(&sample.receiver));
        assert_eq!(sample.bytes, 8 + workload.writes[sample.seq as usize].delta.len() as u64);
    }
    let mut pairs: Vec<(u64, u32)> = latencies.iter().map(|s| (s.seq, s.receiver)).collect();
    pairs.sort_unstable();
    pairs.dedup();
    assert_eq!(pairs.len(), 41 * 3, "one message per (write, receiver)");
    let windows: Vec<ConvergenceWindow> = json_of(&topics["/metrics/convergence"]);
    assert_eq!(windows.len(), 41);
    for window in &windows {
        let slowest = latencies.iter().filter(|s| s.seq == window.seq).map(|s| s.latency_ns).max().unwrap();
        assert_eq!(window.window_ns, slowest.max(1));
    }
    let bandwidth: Vec<BandwidthSample> = json_of(&topics["/metrics/bandwidth"]);
    assert_eq!(bandwidth.iter().map(|b| b.writes).sum::<u64>(), 41);
    assert_eq!(bandwidth.iter().map(|b| b.bytes).sum::<u64>(), result.sample_bytes);
    assert!(bandwidth.windows(2).all(|w| w[1].window_start_ns == w[0].window_start_ns + BANDWIDTH_WINDOW_NS));
    let summaries: Vec<RunSummary> = json_of(&topics["/metrics/summary"]);
    assert_eq!(summaries, vec![summary_of(&result)]);
    assert_eq!(summaries[0].latency.count, 41 * 3);
    assert!(!topics.contains_key(DELTA_TOPIC), "a report run records no deltas");
}

#[test]
fn recorded_deltas_rebuild_the_graph_of_a_replay() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs/sick_tim7xx_scan_10s.mcap");
    let log = Log::open(path, ReadOptions::default()).unwrap();
    let dictionary = replay::bridge::dictionary().unwrap();
    let mut replica = Replica::with_dictionary(ReplicaId(1), dictionary.clone());
    let mut network = InProcNetwork::new(2, 2, &dictionary, 9, 16);
    let mut bridge = Bridge::new(BridgeOptions::default());
    let clock = MonoClock::start();
    let class = Cell::new(PayloadClass::Small);
    let messages = &log.messages[..60];
    let paced = Pacer::new(messages, Rate::Max, 1, || 0)
        .inspect(|item| class.set(PayloadClass::of_schema(item.message.channel.type_name())));
    let recorder = RunRecorder::new(
        Cursor::new(Vec::new()),
        BTreeMap::from([("commit".to_owned(), "test".to_owned()), ("clock".to_owned(), "test".to_owned())]),
    )
    .unwrap();
    let mut sink = RecordingSink::new(&mut network, recorder, "bridge", clock, &class).unwrap();
    let driven = replay::inproc::drive(paced, &mut bridge, &mut replica, &mut sink, |_| {}).unwrap();
    let (mut recorder, live) = sink.finish();
    assert_eq!((live.writes, live.writes_not_everywhere), (driven.deltas, 0));
    let summary = RunSummary {
        run: "sick".into(),
        transport: "inproc".into(),
        agents: 3,
        seed: 9,
        writes: live.writes,
        published_bytes: live.published_bytes,
        latency: live.latency.overall(),
        latency_by_class: BTreeMap::new(),
        convergence: Percentiles::of(&live.convergence),
        writes_not_everywhere: 0,
        end_convergence_ns: None,
        digests_equal: true,
        digests: vec![replica.digest().to_string()],
        writes_recorded: live.writes,
    };
    recorder.summary(clock.now_ns(), &summary).unwrap();
    let (out, _) = recorder.finish().unwrap();
    let topics = check_recording(out.get_ref());

    let deltas = &topics[DELTA_TOPIC];
    assert_eq!(deltas.len() as u64, driven.deltas);
    let mut rebuilt = Replica::with_dictionary(ReplicaId(7), dictionary);
    for (_, bytes) in deltas {
        rebuilt.apply(&Delta::decode(bytes).unwrap()).unwrap();
    }
    assert_eq!(rebuilt.digest(), replica.digest());
    let latencies: Vec<WriteLatency> = json_of(&topics["/metrics/latency"]);
    assert_eq!(latencies.len() as u64, driven.deltas * 2);
    assert!(latencies.iter().any(|s| s.class == PayloadClass::Scan));
    assert!(latencies.iter().any(|s| s.class == PayloadClass::PointCloud));
    let windows: Vec<ConvergenceWindow> = json_of(&topics["/metrics/convergence"]);
    assert_eq!(windows.len() as u64, driven.deltas);
    assert!(windows.iter().all(|w| w.receivers == 2 && w.converged_ns >= w.publish_ns));
    let bandwidth: Vec<BandwidthSample> = json_of(&topics["/metrics/bandwidth"]);
    assert_eq!(bandwidth.iter().map(|b| b.bytes).sum::<u64>(), live.published_bytes);
}

#[test]
fn the_structural_check_catches_messages_that_break_their_schema() {
    let schema = Metric::Latency.schema();
    let sample = WriteLatency {
        seq: 1,
        class: PayloadClass::Image,
        receiver: 1,
        publish_ns: 10,
        apply_ns: 15,
        latency_ns: 5,
        bytes: 100,
    };
    let good = serde_json::to_value(&sample).unwrap();
    conforms(&good, &schema, "m").unwrap();
    let broken = |change: &dyn Fn(&mut serde_json::Map<String, Json>)| {
        let mut value = good.clone();
        change(value.as_object_mut().unwrap());
        conforms(&value, &schema, "m").unwrap_err()
    };
    assert!(broken(&|m| drop(m.remove("seq"))).contains("required `seq`"));
    assert!(broken(&|m| drop(m.insert("extra".into(), json!(1)))).contains("not in the schema"));
    assert!(broken(&|m| drop(m.insert("class".into(), json!("video")))).contains("not in"));
    assert!(broken(&|m| drop(m.insert("latency_ns".into(), json!("5")))).contains("not of type"));
    let summary = Metric::Summary.schema();
    let mut value = serde_json::to_value(RunSummary {
        run: "r".into(),
        transport: "inproc".into(),
        agents: 2,
        seed: 1,
        writes: 0,
        published_bytes: 0,
        latency: Percentiles::default(),
        latency_by_class: BTreeMap::from([("image".to_owned(), Percentiles::default())]),
        convergence: Percentiles::default(),
        writes_not_everywhere: 0,
        end_convergence_ns: None,
        digests_equal: true,
        digests: vec!["ab".into()],
        writes_recorded: 0,
    })
    .unwrap();
    conforms(&value, &summary, "s").unwrap();
    value["latency_by_class"]["image"]["p50_ns"] = json!(-1);
    assert!(conforms(&value, &summary, "s").unwrap_err().contains("s.latency_by_class.image.p50_ns"));
}

#[test]
fn a_message_older_than_the_last_is_refused() {
    let mut recorder = RunRecorder::new(Cursor::new(Vec::new()), BTreeMap::new()).unwrap();
    recorder.published(5_000, 10).unwrap();
    let error = recorder.published(4_000, 10).unwrap_err();
    assert!(error.to_string().contains("never decrease"), "{error}");
    assert!(recorder.delta(0, 6_000, b"x").unwrap_err().to_string().contains("no delta channel"));
}

#[test]
fn file_names_are_plain_and_bounded() {
    assert_eq!(slug("sick_tim7xx_scan_10s.mcap inproc N=3 seed 7"), "sick-tim7xx-scan-10s-inproc-n-3-seed-7");
    assert_eq!(slug("synthetic 16 B @ 200 Hz N=3"), "synthetic-16-b-200-hz-n-3");
    assert_eq!(slug(&"x".repeat(200)).len(), 80);
}

#[test]
fn a_timeline_keeps_a_bounded_number_of_writes() {
    let mut timeline = WriteTimeline::new(2);
    let write = TimelineWrite { class: PayloadClass::Small, bytes: 10, publish_ns: 1 };
    for i in 0..MAX_TIMELINE_WRITES as u64 + 5 {
        timeline.push(write, [Some(i + 2), None]);
    }
    assert_eq!(timeline.writes().len(), MAX_TIMELINE_WRITES);
    assert_eq!(timeline.not_kept(), 5);
    assert_eq!((timeline.applied_ns(3, 0), timeline.applied_ns(3, 1)), (Some(5), None));
}
