//! The report's text against a frozen copy: `report.md` and `results.json` of a fixed, hand-made set of results
//! (no run, no clock) must stay byte for byte what the report wrote before its sections were split into files.
//! The golden files were written by the code before the split (commit 7f61e71's `report.rs`); regenerate them with
//! `UPDATE_GOLDEN=1` only for a change that means to alter the report, and say so in the commit. (Changed since:
//! the "Control traffic against number of agents" section and `results.json`'s `scaling`, added after the split;
//! the "Same-host payloads against the machine's limit" section and `payload_paths`.)

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use measure::Provenance;
use measure::latency::{self, PayloadClass, Percentiles};
use measure::provenance::{DatasetChecksum, Machine};
use measure::results::{
    AgentCost, Bandwidth, FaultRun, KindTraffic, PartitionResult, PayloadCell, PayloadPathsResult, PhaseSummary,
    Results, RolesResult, RunResult, ScalingResult, ScalingRow, StepRecord, Timeline, TimelineResult,
};
use measure::spec::{ExperimentSet, PayloadPath, PayloadPathsExperiment, ScalingExperiment, TimelineExperiment};

const SET: &str = r#"
agents = [2, 4]
seeds = [1]
transports = ["inproc", "rtps-processes"]
[[logs]]
path = "datasets/logs/husky_gps_imu_odom_robot_localization_test1.mcap"
rate = "40"
[payload]
sizes = [16, 360960]
rate_hz = 20
count = 40
agents = 3
transport = "rtps-processes"
[faults]
agents = 4
transports = ["inproc"]
log = { path = "datasets/logs/husky_gps_imu_odom_robot_localization_test1.mcap", rate = "1" }
[[faults.variants]]
label = "no faults"
[[faults.variants]]
label = "delay"
delay_ms = [0.0, 2.0]
[partition]
agents = 3
partition_ms = 300
rate_hz = 100
announce_ms = 100
repetitions = 2
transports = ["inproc"]
[roles]
agents = 3
roles = ["camera-detector"]
log = { path = "datasets/logs/husky_gps_imu_odom_robot_localization_test1.mcap", rate = "1" }
"#;

const ROLES: &str = r#"{"messages": 120, "deltas": 118, "seconds": 3.5, "faults": null, "converged_ms": 200.0,
  "quiesced_after_ms": 1500.0, "digests_equal": true, "agent_reports": [
  {"id": 1, "role": "bridge", "nodes": 12, "digest": "abc", "samples_received": 3, "samples_sent": 118},
  {"id": 2, "role": "camera-detector", "nodes": 12, "digest": "abc", "samples_received": 118, "samples_sent": 4,
   "components": [{"name": "perception::blobs::BlobDetector", "nominal_hz": 20.0, "achieved_hz": 19.5, "runs": 70,
   "misses": 1, "skipped_releases": 0, "lateness_p99_ms": 0.4, "wall_p99_ms": 3.2}]}]}"#;

/// A run with latencies `base_ns × (1..=20)` and convergence windows twice those.
fn run(workload: &str, transport: &str, agents: u32, seed: u64, base_ns: u64) -> RunResult {
    let (mut latencies, mut windows) = (latency::histogram(), latency::histogram());
    for i in 1..=20 {
        latencies.record(base_ns * i).unwrap();
        windows.record(2 * base_ns * i).unwrap();
    }
    let costs = (1..=agents)
        .map(|agent| AgentCost {
            agent,
            kind: if agent == 1 || transport == "inproc" { "thread" } else { "process" },
            cpu_ns: Some(1_000_000 * u64::from(agent)),
            peak_rss_bytes: Some(40 << 20),
        })
        .collect();
    RunResult {
        workload: workload.to_owned(),
        transport: transport.to_owned(),
        agents,
        seed,
        writes: 100,
        sample_bytes: 44_300,
        publish_seconds: 2.5,
        latency: Percentiles::of(&latencies),
        latency_by_class: vec![(PayloadClass::Small, Percentiles::of(&latencies))],
        latency_cdf: latency::cdf(&latencies, 5),
        convergence: Percentiles::of(&windows),
        convergence_cdf: latency::cdf(&windows, 5),
        writes_not_everywhere: 0,
        end_convergence_ns: (seed == 1).then_some(3 * base_ns),
        digests_equal: seed == 1,
        refused: 0,
        bandwidth: Bandwidth {
            source_wire_bytes: 50_000 * u64::from(agents),
            received_bytes: vec![45_000; agents as usize - 1],
            wire_bytes_per_second: 20_000.0 * f64::from(agents),
            received_bytes_per_second: 18_000.0 * f64::from(agents - 1),
            loopback_tx_bytes: (transport != "inproc").then_some(70_000 * u64::from(agents)),
            loopback_tx_bytes_per_second: (transport != "inproc").then_some(28_000.0 * f64::from(agents)),
            dropped_full: 0,
            injected_drops: 0,
            injected_duplicates: 2,
        },
        process_peak_rss_bytes: Some(80 << 20),
        agent_costs: costs,
        start_attempts: 1,
        latency_histogram: latencies,
        convergence_histogram: windows,
        timeline: Default::default(),
    }
}

/// Two groups of the control-traffic simulation, numbers made by hand.
fn scaling() -> ScalingResult {
    let row = |agents: u32, announces: u64, announce_bytes: u64| {
        let received = u64::from(agents - 1);
        let kinds = BTreeMap::from([
            (
                "announce".to_owned(),
                KindTraffic {
                    samples_sent: announces,
                    bytes_sent: announces * announce_bytes,
                    samples_received: announces * received,
                    bytes_received: announces * announce_bytes * received,
                },
            ),
            (
                "delta".to_owned(),
                KindTraffic {
                    samples_sent: 1_000,
                    bytes_sent: 45_000,
                    samples_received: 1_000 * received,
                    bytes_received: 45_000 * received,
                },
            ),
            ("deltas".to_owned(), KindTraffic { samples_sent: 2, bytes_sent: 300, ..KindTraffic::default() }),
        ]);
        ScalingRow { agents, window_ms: 10_000, writes: 1_000, kinds, converged: true }
    };
    ScalingResult {
        experiment: ScalingExperiment {
            agents: vec![8, 32],
            writers: 4,
            write_rate_hz: 100.0,
            window_ms: 10_000,
            announce_ms: 500,
            announce_group: 8,
            seed: 1,
        },
        rows: vec![row(8, 160, 90), row(32, 160, 90)],
    }
}

/// The payload paths for one size to 1 receiver, every path, numbers made by hand.
fn payload_paths() -> PayloadPathsResult {
    let experiment = PayloadPathsExperiment {
        sizes: vec![4 << 20],
        receivers: vec![1],
        paths: PayloadPath::all(),
        count: 20,
        rate_hz: 20.0,
        warmup: 3,
        steady_max: 0,
    };
    let cell = |path: PayloadPath, p50_ns: u64, cpu: Option<f64>, loopback: Option<f64>| PayloadCell {
        path,
        size_bytes: 4 << 20,
        receivers: u32::from(path.has_receivers()),
        expected: 20,
        latency: Percentiles {
            count: 20,
            p50_ns,
            p90_ns: 2 * p50_ns,
            p99_ns: 3 * p50_ns,
            p999_ns: 3 * p50_ns,
            max_ns: 4 * p50_ns,
            mean_ns: 1.5 * p50_ns as f64,
        },
        cpu_ns_per_sample: cpu,
        loopback_bytes_per_sample: loopback,
        to_iceoryx2: None,
        session_starts: 1,
    };
    let cells = vec![
        cell(PayloadPath::Agents(agent::Link::Shm), 3_000_000, Some(2_400_000.0), Some(0.0)),
        cell(PayloadPath::Memcpy, 67_000, None, None),
        cell(PayloadPath::Agents(agent::Link::Rtps), 8_900_000, Some(5_300_000.0), Some(4_200_207.5)),
        cell(PayloadPath::Iceoryx2, 290_000, Some(44_000.0), Some(0.0)),
    ];
    PayloadPathsResult::new(experiment, true, "0.50 0.40 0.30 1/100 7".into(), cells)
}

fn timeline() -> TimelineResult {
    let experiment = TimelineExperiment {
        log: "datasets/logs/euroc_v1_01_easy_cam0_1s.mcap".into(),
        period_ms: 50,
        duration_ms: 300,
        overload_from_ms: 100,
        overload_until_ms: 200,
        overload_period_ms: 100,
        overload_busy_ms: 120,
        window_ms: 100,
        miss_tolerance_us: 1000,
    };
    let steps: Vec<StepRecord> = (0..6)
        .map(|i| StepRecord {
            release_ns: i * 50_000_000,
            start_ns: i * 50_000_000 + 1_000 * i * i,
            finish_ns: i * 50_000_000 + 3_000_000,
            lateness_ns: 1_000 * i * i,
            skipped_releases: u64::from(i == 3),
            miss: i == 3,
        })
        .collect();
    let phase = |name: &str, from_ns, until_ns| PhaseSummary {
        name: name.to_owned(),
        from_ns,
        until_ns,
        steps: 2,
        frequency_hz: 20.0,
        lateness_max_ns: until_ns / 1000,
        lateness_mean_ns: until_ns / 2000,
        misses: u64::from(name == "during"),
        skipped_releases: u64::from(name == "during"),
        step_mean_ns: 3_000_000,
    };
    TimelineResult {
        experiment,
        clock: "MonotonicClock".into(),
        detector: "perception::blobs::BlobDetector".into(),
        overload_component: "measure::timeline::Overload".into(),
        log_frames: 20,
        frames_written: 6,
        overload_busy_steps: 1,
        counters: Default::default(),
        step_failures: 0,
        trace_dropped: 0,
        timeline: Timeline {
            steps,
            frequency: (1..=20).map(|i| (i * 10_000_000, 20.0 - f64::from(i as u32 % 3))).collect(),
            phases: vec![
                phase("before", 0, 100_000_000),
                phase("during", 100_000_000, 200_000_000),
                phase("after", 200_000_000, 300_000_000),
            ],
            lateness_max_ns: 25_000,
            misses: 1,
            skipped_releases: 1,
            top_level_steps: 12,
            overlaps: 0,
        },
    }
}

fn results() -> Results {
    let set: ExperimentSet = toml::from_str(SET).unwrap();
    let husky = "husky_gps_imu_odom_robot_localization_test1.mcap";
    let mut replay = Vec::new();
    for (i, transport) in ["inproc", "rtps-processes"].into_iter().enumerate() {
        for agents in [2, 4] {
            replay.push(run(husky, transport, agents, 1, 100_000 * (i as u64 + 1) * u64::from(agents)));
        }
    }
    let payload = vec![run("synthetic 16 B", "rtps-processes", 3, 1, 200_000), {
        run("synthetic 360960 B", "rtps-processes", 3, 1, 900_000)
    }];
    let faults = vec![
        FaultRun { label: "no faults".into(), run: run(husky, "inproc", 4, 1, 150_000) },
        FaultRun { label: "delay".into(), run: run(husky, "inproc+faults", 4, 2, 450_000) },
    ];
    let partition = (1..=2)
        .map(|seed| PartitionResult {
            transport: "inproc".into(),
            agents: 3,
            seed,
            partition_ms: 300,
            announce_period_ms: 100,
            writes: 60,
            dropped: 30,
            reconverge_ns: (seed == 1).then_some(120_000_000),
        })
        .collect();
    let provenance = Provenance {
        schema_version: measure::SCHEMA_VERSION,
        commit: "0123456789abcdef0123456789abcdef01234567".into(),
        dirty: Some(false),
        rustc: "rustc 1.0.0".into(),
        release_build: true,
        machine: Machine {
            cpus: 2,
            cpu_model: "test cpu".into(),
            memory_bytes: Some(1 << 30),
            kernel: "6.1".into(),
            load_average_1m: Some(1.5),
        },
        command: "cortex report".into(),
        started_unix_s: 1_700_000_000,
        seeds: BTreeMap::from([("replay[0]".to_owned(), 1)]),
        datasets: vec![DatasetChecksum {
            file: husky.into(),
            bytes: 1234,
            sha256: "ff".repeat(32),
            manifest_sha256: Some("ff".repeat(32)),
        }],
        network: "host network namespace; RTPS multicast on".into(),
    };
    Results {
        provenance,
        experiment: "golden".into(),
        mode: "quick".into(),
        set,
        replay,
        payload,
        faults,
        partition,
        timeline: Some(timeline()),
        roles: Some(serde_json::from_str::<RolesResult>(ROLES).unwrap()),
        scaling: Some(scaling()),
        payload_paths: Some(payload_paths()),
        seconds: 12.5,
    }
}

fn golden(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden").join(name)
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("measure-golden-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// A run whose receivers were started again is named in the provenance table (the frozen copy has none).
#[test]
fn a_run_started_again_is_named_where_the_report_says_how_it_was_obtained() {
    let mut results = results();
    results.replay[0].start_attempts = 2;
    let out = temp_dir("restarted");
    measure::report::write(&results, &out).unwrap();
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    let row = report.lines().find(|line| line.starts_with("| runs started again |")).expect("the row");
    let run = &results.replay[0];
    let named =
        format!("{} over {} with {} agents, seed {}: 2 starts", run.workload, run.transport, run.agents, run.seed);
    assert!(row.contains(&named), "{row}");
    let json = std::fs::read_to_string(out.join("results.json")).unwrap();
    assert_eq!(json.matches("\"start_attempts\"").count(), 1, "only the restarted run carries the count");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn report_text_matches_the_frozen_copy() {
    let out = temp_dir("report");
    measure::report::write(&results(), &out).unwrap();
    for file in ["report.md", "results.json"] {
        let written = std::fs::read_to_string(out.join(file)).unwrap();
        if std::env::var_os("UPDATE_GOLDEN").is_some() {
            std::fs::write(golden(file), &written).unwrap();
        }
        let frozen = std::fs::read_to_string(golden(file)).unwrap();
        assert!(
            written == frozen,
            "{file} differs from tests/golden/{file}; diff {} against it",
            out.join(file).display()
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}
