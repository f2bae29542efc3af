//! `cortex replay` and `cortex datasets verify` from the command line: a bundled log replays in process with 3
//! agents to equal digests, a damaged file is an error that says where (or a recovered prefix with `--recover`), a
//! log replays over RTPS from the bridge into agent processes (plain, and a BICA role) to equal digests, and a log
//! that does not match the manifest fails the check.
//! `--out DIR` records the run as `DIR/run.mcap`, which both MCAP readers open and whose deltas rebuild the graph.
//! The same log as a ROS 1 bag (bz2, lz4), ROS 1 MCAP or rosbag2 directory (sqlite3, mcap) replays to the same graph
//! and counts; custom messages are decoded from their definitions (or carried opaque); a damaged bag or sqlite file
//! is an error that says where, and `--recover` replays what is readable.

use std::path::{Path, PathBuf};
use std::process::Command;

fn cortex(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cortex")).args(args).output().expect("cortex runs")
}

fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path).display().to_string()
}

#[test]
fn bundled_log_replays_to_equal_digests() {
    let log = repo("datasets/logs/ouster_os1-128_1scan.mcap");
    let out = cortex(&["replay", &log, "--agents", "3", "--rate", "max", "--loop", "2", "--opaque", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON summary");
    assert_eq!(summary["digests_equal"], true);
    assert_eq!(summary["digests"].as_array().unwrap().len(), 3);
    assert_eq!(summary["messages"], 2 * 20);
    assert_eq!(summary["bridge"]["decoded"]["sensor_msgs/msg/PointCloud2"], 2);
    assert_eq!(summary["bridge"]["unknown"]["ouster_sensor_msgs/msg/PacketMsg"], 2 * 18);
    assert_eq!(summary["bridge"]["opaque"], 2 * 19);
    let out = cortex(&["replay", &log, "--rate", "max", "--topics", "/ouster/points"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("19 filtered out") && text.contains("digests       equal"), "{text}");
}

#[test]
fn damaged_files_and_bad_arguments_are_errors() {
    let out = cortex(&["replay", &repo("impl/replay/tests/fixtures/chunk_not_closed.mcap")]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("chunk record at byte 39: truncated"), "{stderr}");
    let padded = repo("impl/replay/tests/fixtures/zstd_chunk_with_padding.mcap");
    let out = cortex(&["replay", &padded]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("undefined channel 0"));
    let out = cortex(&["replay", &padded, "--recover", "--rate", "max"]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("replaying the 0 messages read before it"));
    let log = repo("datasets/logs/ouster_os1-128_1scan.mcap");
    let out = cortex(&["replay", &log, "--roles", "camera-detector"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--roles needs --transport rtps"));
    let out = cortex(&["replay", &log, "--transport", "rtps", "--agents", "2", "--roles", "attention,attention"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("2 roles given for 1 agent processes"));
    let out = cortex(&["replay", &log, "--transport", "rtps", "--roles", "bridge"]);
    assert_eq!(out.status.code(), Some(2), "a usage error");
}

#[test]
fn a_log_replays_over_rtps_into_agent_processes() {
    let log = repo("datasets/logs/euroc_v1_01_easy_cam0_1s.mcap");
    let dir = std::env::temp_dir().join(format!("cortex-replay-rtps-{}", std::process::id()));
    let args = ["replay", &log, "--transport", "rtps", "--domain", "78", "--rate", "4", "--json"];
    let out = cortex(&[&args[..], &["--agents", "2", "--out", dir.to_str().unwrap()]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON summary");
    assert_eq!(summary["transport"], "rtps");
    assert_eq!(summary["digests_equal"], true);
    assert_eq!(summary["messages"], 281);
    assert_eq!(summary["bridge"]["decoded"]["sensor_msgs/msg/Image"], 20);
    let agents = summary["agent_reports"].as_array().unwrap();
    assert_eq!(agents.len(), 2);
    assert_eq!(agents[0]["role"], "bridge");
    assert!(agents[0]["nodes"].as_u64().unwrap() >= 5 && agents[1]["nodes"] == agents[0]["nodes"]);
    // Not one sample per delta: deltas published before discovery matched the receiver come in repair batches (one
    // sample, many deltas), which is how the multicast run in CI once ended with fewer samples than deltas.
    assert!(agents[1]["samples_received"].as_u64().unwrap() > 0);
    assert!(summary["converged_ms"].is_f64());
    // `--out`: the deltas the bridge published, which rebuild its graph.
    let deltas = summary["deltas"].as_u64().unwrap();
    assert_eq!(summary["recording"]["messages"]["/dsr/deltas"], deltas);
    let recorded = replay::log::Log::open(dir.join("run.mcap"), replay::log::ReadOptions::default()).unwrap();
    let mut replica = dsr::Replica::with_dictionary(dsr::ReplicaId(9), replay::bridge::dictionary().unwrap());
    for message in recorded.messages.iter().filter(|m| m.channel.topic == "/dsr/deltas") {
        replica.apply(&dsr::Delta::decode(&message.data).unwrap()).unwrap();
    }
    assert_eq!(replica.digest().to_string(), summary["digests"][0].as_str().unwrap());
    let _ = std::fs::remove_dir_all(&dir);

    // A BICA role in one of the processes: quiesced after the replay, then every graph is equal.
    let out = cortex(&[&args[..], &["--agents", "3", "--roles", "camera-detector"]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON summary");
    assert_eq!(summary["digests_equal"], true);
    let roles: Vec<_> = summary["agent_reports"].as_array().unwrap().iter().map(|a| a["role"].clone()).collect();
    assert_eq!(roles, ["bridge", "camera-detector", "plain"]);
    let detector = &summary["agent_reports"][1];
    assert!(detector["components_error"].is_null(), "{detector}");
    let components = detector["components"].as_array().unwrap();
    assert!(components.iter().any(|c| c["runs"].as_u64().unwrap() > 0), "{detector}");
}

#[test]
fn a_replay_configuration_file_with_faults_over_rtps_converges() {
    let dir = std::env::temp_dir().join(format!("cortex-replay-config-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("experiments")).unwrap();
    let config = dir.join("experiments/replay.toml");
    let log = repo("datasets/logs/euroc_v1_01_easy_cam0_1s.mcap");
    std::fs::write(
        &config,
        format!(
            "log = {log:?}\nagents = 3\ntransport = \"rtps\"\nrate = \"4\"\ndomain = 78\n\
             faults = \"loss=0.1,duplicate=0.05\"\n"
        ),
    )
    .unwrap();
    let out = cortex(&["replay", "--config", config.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON summary");
    assert_eq!((summary["transport"].as_str(), summary["agents"].as_u64()), (Some("rtps"), Some(3)));
    assert!(summary["faults"].as_str().unwrap().starts_with("loss=0.1,duplicate=0.05,"), "{summary}");
    assert_eq!(summary["digests_equal"], true, "lost samples repaired by anti-entropy");
    // The command line wins over the file.
    let out = cortex(&["replay", "--config", config.to_str().unwrap(), "--transport", "inproc", "--faults", "none"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("over inproc with 3 agents"));

    std::fs::write(&config, "agents = 3\nspeed = 2\n").unwrap();
    let out = cortex(&["replay", "--config", config.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not a valid replay configuration") && stderr.contains("speed"), "{stderr}");
    std::fs::write(&config, format!("log = {log:?}\nroles = [\"painter\"]\ntransport = \"rtps\"\n")).unwrap();
    let out = cortex(&["replay", "--config", config.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("field `roles`"), "{}", String::from_utf8_lossy(&out.stderr));
    let out = cortex(&["replay", &log, "--faults", "loss=0.1"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("--faults needs --transport rtps"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn datasets_verify_passes_and_catches_a_changed_file() {
    let out = cortex(&["datasets", "verify", "--dir", &repo("datasets/logs"), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(report["files"].as_array().unwrap().iter().all(|file| file["ok"] == true));

    // A copy of the manifest with one file replaced by a damaged copy and one missing.
    let dir = std::env::temp_dir().join(format!("cortex-datasets-verify-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let source = PathBuf::from(repo("datasets/logs"));
    std::fs::copy(source.join("manifest.json"), dir.join("manifest.json")).unwrap();
    let mut husky = std::fs::read(source.join("husky_gps_imu_odom_robot_localization_test1.mcap")).unwrap();
    husky[1000] ^= 1;
    std::fs::write(dir.join("husky_gps_imu_odom_robot_localization_test1.mcap"), husky).unwrap();
    std::fs::copy(source.join("sick_tim7xx_scan_10s.mcap"), dir.join("sick_tim7xx_scan_10s.mcap")).unwrap();
    let out = cortex(&["datasets", "verify", "--dir", &dir.display().to_string()]);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("husky_gps_imu_odom_robot_localization_test1.mcap     CHECKSUM MISMATCH"), "{stdout}");
    assert!(stdout.contains("sick_tim7xx_scan_10s.mcap                            ok"), "{stdout}");
    assert!(stdout.contains("euroc_v1_01_easy_cam0_1s.mcap                        MISSING"), "{stdout}");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(source.join("manifest.json")).unwrap()).unwrap();
    let total = 4 + manifest["containers"].as_array().unwrap().len();
    let expected = format!("{} of {total} files", total - 1);
    assert!(String::from_utf8_lossy(&out.stderr).contains(&expected), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn replay_out_records_a_run_that_rebuilds_the_graph() {
    let dir = std::env::temp_dir().join(format!("cortex-replay-out-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let log = repo("datasets/logs/husky_gps_imu_odom_robot_localization_test1.mcap");
    let args = ["replay", &log, "--agents", "3", "--rate", "max", "--json", "--out", dir.to_str().unwrap()];
    let out = cortex(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON summary");
    let deltas = summary["deltas"].as_u64().unwrap();
    assert!(deltas > 100, "{summary}");
    let path = dir.join("run.mcap");
    assert_eq!(summary["recording"]["path"], path.display().to_string());
    assert_eq!(summary["recording"]["messages"]["/dsr/deltas"], deltas);

    // The `mcap` crate: an indexed file with statistics that agree with the summary printed.
    let bytes = std::fs::read(&path).unwrap();
    let index = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
    let stats = index.stats.expect("statistics");
    assert!(!index.chunk_indexes.is_empty());
    let mut topics: Vec<(String, String, String)> = index
        .channels
        .values()
        .map(|c| {
            let schema = c.schema.as_ref().map_or(String::new(), |s| format!("{} {}", s.name, s.encoding));
            (c.topic.clone(), c.message_encoding.clone(), schema)
        })
        .collect();
    topics.sort();
    let expected = [
        ("/dsr/deltas", "dsr-delta-v1", "dsr.Delta "),
        ("/metrics/bandwidth", "json", "cortex.BandwidthSample jsonschema"),
        ("/metrics/convergence", "json", "cortex.ConvergenceWindow jsonschema"),
        ("/metrics/latency", "json", "cortex.WriteLatency jsonschema"),
        ("/metrics/summary", "json", "cortex.RunSummary jsonschema"),
    ];
    let expected: Vec<(String, String, String)> =
        expected.iter().map(|(a, b, c)| ((*a).to_owned(), (*b).to_owned(), (*c).to_owned())).collect();
    assert_eq!(topics, expected);
    let mut last = 0;
    let mut latencies = 0;
    let mut recorded_summary = None;
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        assert!(message.log_time >= last);
        last = message.log_time;
        if message.channel.message_encoding == "json" {
            let schema: serde_json::Value =
                serde_json::from_slice(&message.channel.schema.as_ref().unwrap().data).unwrap();
            let value: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
            for key in schema["required"].as_array().unwrap() {
                assert!(value.get(key.as_str().unwrap()).is_some(), "{} lacks {key}", message.channel.topic);
            }
            match message.channel.topic.as_str() {
                "/metrics/latency" => latencies += 1,
                "/metrics/summary" => recorded_summary = Some(value),
                _ => {}
            }
        }
    }
    assert_eq!(stats.message_count, stats.channel_message_counts.values().sum::<u64>());
    assert_eq!(latencies, deltas * 2, "one latency per delta and receiver");
    let recorded_summary = recorded_summary.expect("a summary message");
    assert_eq!(recorded_summary["digests"], summary["digests"]);
    assert_eq!(recorded_summary["writes"], deltas);

    // The project's reader: the deltas, applied in order to an empty replica, give the bridge's digest.
    let log = replay::log::Log::open(&path, replay::log::ReadOptions::default()).unwrap();
    let mut replica = dsr::Replica::with_dictionary(dsr::ReplicaId(9), replay::bridge::dictionary().unwrap());
    let mut applied = 0;
    for message in log.messages.iter().filter(|m| m.channel.topic == "/dsr/deltas") {
        assert_eq!(message.channel.type_name(), "dsr.Delta");
        replica.apply(&dsr::Delta::decode(&message.data).unwrap()).unwrap();
        applied += 1;
    }
    assert_eq!(applied, deltas);
    assert_eq!(replica.digest().to_string(), summary["digests"][0].as_str().unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `cortex replay --rate max --json` of a log: the summary.
fn replay_json(log: &str, extra: &[&str]) -> serde_json::Value {
    let out = cortex(&[&["replay", log, "--rate", "max", "--json"][..], extra].concat());
    assert!(out.status.success(), "{log}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("JSON summary")
}

#[test]
fn every_container_of_a_log_replays_to_the_same_graph() {
    let reference = replay_json(&repo("datasets/logs/containers/husky_10s.mcap"), &[]);
    assert_eq!(reference["container"], "mcap");
    assert_eq!(reference["bridge"]["decoded"]["sensor_msgs/msg/Imu"], 301);
    for (name, container) in [
        ("husky_10s.bag", "ros1 bag"),
        ("husky_10s_bz2.bag", "ros1 bag"),
        ("husky_10s_lz4.bag", "ros1 bag"),
        ("husky_10s_ros1.mcap", "mcap"),
        ("husky_10s_sqlite3", "rosbag2 sqlite3"),
        ("husky_10s_rosbag2_mcap", "rosbag2 mcap"),
    ] {
        let summary = replay_json(&repo(&format!("datasets/logs/containers/{name}")), &[]);
        assert_eq!(summary["container"], container, "{name}");
        assert_eq!(summary["digests_equal"], true, "{name}");
        assert_eq!(summary["digests"][0], reference["digests"][0], "{name}: the same graph");
        assert_eq!(summary["bridge"]["decoded"], reference["bridge"]["decoded"], "{name}");
        assert_eq!(summary["deltas"], reference["deltas"], "{name}");
    }
}

#[test]
fn custom_messages_are_described_or_carried_opaque() {
    let log = repo("datasets/logs/containers/custom_radar_diag.bag");
    let summary = replay_json(&log, &[]);
    assert_eq!(summary["bridge"]["described"]["acme_radar_msgs/msg/RadarScan"], 10);
    assert_eq!(summary["bridge"]["described"]["diagnostic_msgs/msg/DiagnosticArray"], 10);
    assert_eq!(summary["digests_equal"], true);
    let summary = replay_json(&log, &["--opaque"]);
    assert_eq!(summary["bridge"]["unknown"]["acme_radar_msgs/msg/RadarScan"], 10);
    assert_eq!(summary["bridge"]["opaque"], 20);
    let out = cortex(&["replay", &repo("datasets/logs/containers/custom_radar_diag_sqlite3"), "--rate", "max"]);
    let text = String::from_utf8_lossy(&out.stdout);
    let described =
        text.lines().any(|line| line.starts_with("  described") && line.ends_with("10  acme_radar_msgs/msg/RadarScan"));
    assert!(text.contains("(rosbag2 sqlite3, ") && described, "{text}");
}

/// Over RTPS every agent process has the built-in dictionary: the names the log defines reach it anyway (the bridge
/// teaches them to its graph, the receiver learns them from the deltas), so nothing is refused.
#[test]
fn custom_messages_replicate_to_agent_processes_with_the_built_in_dictionary() {
    let log = repo("datasets/logs/containers/custom_radar_diag_ros1.mcap");
    let summary = replay_json(&log, &["--transport", "rtps", "--agents", "2", "--domain", "79"]);
    assert_eq!(summary["bridge"]["described"]["acme_radar_msgs/msg/RadarScan"], 10, "{summary}");
    assert_eq!(summary["bridge"]["errors"], serde_json::json!({}), "{summary}");
    assert_eq!(summary["digests_equal"], true, "{summary}");
    let agents = summary["agent_reports"].as_array().unwrap();
    assert!(agents.iter().all(|agent| agent["nodes"] == 3), "{summary}");
}

#[test]
fn damaged_bag_and_sqlite_are_errors_that_say_where_and_recover() {
    let dir = std::env::temp_dir().join(format!("cortex-replay-damaged-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bag = std::fs::read(repo("datasets/logs/containers/husky_10s_lz4.bag")).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bag[..bag.len() / 2]).unwrap();
    let out = cortex(&["replay", cut.to_str().unwrap(), "--rate", "max"]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("cut.mcap: ") && stderr.contains(" record at byte ") && stderr.contains("truncated"),
        "{stderr}"
    );
    let summary = replay_json(cut.to_str().unwrap(), &["--recover"]);
    assert_eq!(summary["container"], "ros1 bag", "detected from the content, not the name");
    assert!(summary["messages"].as_u64().unwrap() > 0 && summary["damage"].is_string());
    let db_dir = dir.join("bag");
    std::fs::create_dir_all(&db_dir).unwrap();
    let source = PathBuf::from(repo("datasets/logs/containers/husky_10s_sqlite3"));
    std::fs::copy(source.join("metadata.yaml"), db_dir.join("metadata.yaml")).unwrap();
    let mut db = std::fs::read(source.join("husky_10s_sqlite3.db3")).unwrap();
    db[30 * 4096..31 * 4096].fill(0xA5);
    std::fs::write(db_dir.join("husky_10s_sqlite3.db3"), &db).unwrap();
    let out = cortex(&["replay", db_dir.to_str().unwrap(), "--rate", "max"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(" of table `messages`: sqlite: database disk image is malformed"), "{stderr}");
    let summary = replay_json(db_dir.to_str().unwrap(), &["--recover"]);
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(summary["damage"].as_str().unwrap().contains(" of table `messages`"), "{summary}");
    assert!(summary["messages"].as_u64().unwrap() > 100, "{summary}");
}
