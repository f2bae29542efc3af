//! `cortex report` end to end on a tiny experiment file: every figure (SVG and PNG) and every section of
//! `report.md` exists, `results.json` carries the schema version and provenance, and the report says which
//! transport its figures used; every run is recorded as an MCAP file under `runs/` that the `mcap` crate and the
//! project's reader open, linked from the report. Also: a malformed experiment file is refused with a message naming the field.

use std::path::{Path, PathBuf};
use std::process::Command;

fn cortex(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cortex")).args(args).output().expect("cortex runs")
}

fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path).display().to_string()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cortex-report-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("experiments")).unwrap();
    dir
}

fn tiny_set(euroc: &str, sick: &str) -> String {
    format!(
        r#"agents = [2, 3]
seeds = [7]
transports = ["inproc", "rtps-processes"]
rtps_domain = 76
logs = [{{ path = "{sick}", rate = "20" }}, {{ path = "{euroc}", rate = "4" }}]
[payload]
sizes = [16, 65536]
rate_hz = 200
count = 5
agents = 3
transport = "rtps-processes"
[faults]
agents = 3
transports = ["inproc", "rtps-processes"]
log = {{ path = "{euroc}", rate = "4" }}
variants = [{{ label = "no faults" }}, {{ label = "delayed", delay_ms = [0.0, 1.0], duplicate = 0.1 }}]
[partition]
agents = 2
partition_ms = 50
rate_hz = 100
announce_ms = 50
repetitions = 1
transports = ["inproc", "rtps"]
[roles]
log = {{ path = "{euroc}", rate = "4" }}
agents = 3
roles = ["camera-detector"]
faults = "loss=0.1"
[timeline]
log = "{euroc}"
period_ms = 50
duration_ms = 1500
overload_from_ms = 500
overload_until_ms = 1000
overload_period_ms = 100
overload_busy_ms = 120
window_ms = 250
[scaling]
agents = [2, 4]
writers = 2
write_rate_hz = 50
window_ms = 500
announce_ms = 100
seed = 3
"#
    )
}

/// Runs `cortex report` on an experiment file `name` whose `quick` and `full` sets are both `set` (which starts with
/// its `agents` line); returns the output directory and the command's output, which must have succeeded.
fn run_report(name: &str, set: &str) -> (PathBuf, std::process::Output) {
    let dir = scratch(name);
    let agents = set.lines().next().unwrap();
    let config = format!(
        "name = \"{name}\"\ndescription = \"test\"\n{}{}",
        set.replace("\n[", "\n[quick.").replacen(agents, &format!("[quick]\n{agents}"), 1),
        set.replace("\n[", "\n[full.").replacen(agents, &format!("[full]\n{agents}"), 1)
    );
    let config_path = dir.join(format!("experiments/{name}.toml"));
    std::fs::write(&config_path, config).unwrap();
    let out = dir.join("out");
    let output = cortex(&["report", "--config", config_path.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    (out, output)
}

#[test]
fn tiny_report_has_every_figure_and_section() {
    let (euroc, sick) =
        (repo("datasets/logs/euroc_v1_01_easy_cam0_1s.mcap"), repo("datasets/logs/sick_tim7xx_scan_10s.mcap"));
    let (out, output) = run_report("tiny", &tiny_set(&euroc, &sick));
    assert!(String::from_utf8_lossy(&output.stdout).contains("report tiny (quick)"));
    // Not on a terminal, progress is one line per finished run.
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.lines().any(|line| line.starts_with("run 1/") && line.contains(" left")), "{stderr}");

    for stem in measure::report::figure_stems() {
        let svg = std::fs::read_to_string(out.join(format!("{stem}.svg"))).unwrap();
        assert!(svg.contains("<svg") && svg.contains("commit"), "{stem}.svg names no commit");
        let png = std::fs::read(out.join(format!("{stem}.png"))).unwrap();
        assert_eq!(&png[1..4], b"PNG", "{stem}.png");
    }
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    let mut last = 0;
    // Every section in order, the timeline's before "Not measured yet".
    for section in measure::report::headings() {
        let at = report.find(section).unwrap_or_else(|| panic!("missing section {section}"));
        assert!(at >= last, "section {section} out of order");
        last = at;
    }
    for stem in measure::report::figure_stems() {
        assert!(report.contains(&format!("]({stem}.svg)")), "report.md does not show {stem}");
    }
    assert!(report.contains("**every receiver is a separate process**"));
    assert!(report.contains("rtps-processes"));
    assert!(report.contains("measured elsewhere"));

    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(results["provenance"]["schema_version"], measure::SCHEMA_VERSION);
    let network = results["provenance"]["network"].as_str().unwrap();
    assert!(network.contains("network namespace") && network.contains("RTPS multicast"), "{network}");
    assert!(report.contains(&format!("| network | {network} |")));
    assert_eq!(results["mode"], "quick");
    let replay = results["replay"].as_array().unwrap();
    assert_eq!(replay.len(), 8, "2 logs x 2 transports x 2 agent counts x 1 seed");
    assert!(replay.iter().all(|r| r["digests_equal"] == true && r["writes_not_everywhere"] == 0));
    let processes: Vec<_> = replay.iter().filter(|r| r["transport"] == "rtps-processes").collect();
    assert_eq!(processes.len(), 4);
    for run in processes {
        let costs = run["agent_costs"].as_array().unwrap();
        assert_eq!(costs.len() as u64, run["agents"].as_u64().unwrap());
        assert!(costs[1..].iter().all(|c| c["kind"] == "process" && c["peak_rss_bytes"].as_u64().unwrap() > 0));
    }
    let faults = results["faults"].as_array().unwrap();
    assert_eq!(faults.len(), 4, "2 variants x 2 transports");
    assert!(faults.iter().any(|f| f["run"]["transport"] == "rtps-processes+faults"));
    assert!(faults.iter().all(|f| f["run"]["digests_equal"] == true));
    assert!(results["payload"].as_array().unwrap().iter().all(|r| r["transport"] == "rtps-processes"));
    assert_eq!(results["provenance"]["datasets"].as_array().unwrap().len(), 2);
    assert!(results["provenance"]["datasets"].as_array().unwrap().iter().all(|d| d["sha256"] == d["manifest_sha256"]));
    assert!(results["partition"][0]["reconverge_ns"].is_u64());
    assert_eq!(results["partition"][1]["transport"], "rtps");
    assert!(results["partition"][1]["reconverge_ns"].is_u64());

    // One MCAP file per replay, payload and fault run, each linked from report.md.
    let mut runs: Vec<PathBuf> = std::fs::read_dir(out.join("runs")).unwrap().map(|e| e.unwrap().path()).collect();
    runs.sort();
    assert_eq!(runs.len(), 8 + 2 + 4, "{runs:?}");
    let mut replay_latencies = 0;
    for path in &runs {
        let name = path.file_name().unwrap().to_str().unwrap();
        assert!(report.contains(&format!("](runs/{name})")), "report.md does not link {name}");
        let bytes = std::fs::read(path).unwrap();
        let index = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
        assert_eq!(index.channels.len(), 4, "{name}: the metric channels");
        let mut summaries = Vec::new();
        for message in mcap::MessageStream::new(&bytes).unwrap() {
            let message = message.unwrap();
            let value: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
            match message.channel.topic.as_str() {
                "/metrics/summary" => summaries.push(value),
                "/metrics/latency" if name.starts_with("replay") => replay_latencies += 1,
                _ => {}
            }
        }
        assert_eq!(summaries.len(), 1, "{name}");
        let log = replay::log::Log::open(path, replay::log::ReadOptions::default()).unwrap();
        assert_eq!(log.messages.len() as u64, index.stats.unwrap().message_count, "{name}");
        let latency_count = summaries[0]["latency"]["count"].as_u64().unwrap();
        assert!(latency_count > 0, "{name}");
    }
    let expected: u64 =
        results["replay"].as_array().unwrap().iter().map(|r| r["latency"]["count"].as_u64().unwrap()).sum();
    assert_eq!(replay_latencies, expected, "one latency message per (write, receiver) of every replay run");
    // The roles replay: real agent processes, the detector's statistics by remote call, equal digests despite loss.
    let roles = &results["roles"];
    assert_eq!(roles["digests_equal"], true, "{roles}");
    assert_eq!(roles["agents"].as_array().unwrap().len(), 3);
    assert_eq!(roles["agents"][1]["role"], "camera-detector");
    let components = roles["agents"][1]["components"].as_array();
    assert!(components.is_some_and(|c| c.iter().any(|c| c["runs"].as_u64() > Some(0))), "{roles}");
    assert!(report.contains("## Detector roles over RTPS"));

    // Control traffic against the number of agents: one row per group, every group converged.
    let scaling = results["scaling"]["rows"].as_array().unwrap();
    assert_eq!(scaling.iter().map(|row| row["agents"].as_u64().unwrap()).collect::<Vec<_>>(), [2, 4]);
    assert!(
        scaling
            .iter()
            .all(|row| row["converged"] == true && row["kinds"]["announce"]["samples_sent"].as_u64() > Some(0))
    );
    assert!(report.contains("## Control traffic against number of agents"));

    // The timeline ran on the real clock, so only what the scheduler guarantees whatever the timing is checked.
    let timeline = &results["timeline"];
    assert_eq!(timeline["clock"], "bica::clock::MonotonicClock");
    assert_eq!(timeline["timeline"]["overlaps"], 0);
    assert_eq!(timeline["trace_dropped"], 0);
    let steps = timeline["timeline"]["steps"].as_array().unwrap();
    assert!(!steps.is_empty());
    assert_eq!(timeline["counters"]["runs"], steps.len());
    assert!(steps.windows(2).all(|w| w[0]["finish_ns"].as_u64() <= w[1]["start_ns"].as_u64()));
    assert!(timeline["overload_busy_steps"].as_u64().unwrap() > 0);
    let _ = std::fs::remove_dir_all(out.parent().unwrap());
}

#[test]
fn malformed_experiment_file_is_refused_naming_the_field() {
    let dir = scratch("bad");
    let config_path = dir.join("experiments/bad.toml");
    std::fs::write(&config_path, "name = \"bad\"\ndescription = \"x\"\nspeed = 3\n").unwrap();
    let output = cortex(&["report", "--config", config_path.to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("not a valid experiment file") && stderr.contains("speed"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn experiment_files_take_logs_in_any_container() {
    let (bag, sqlite, ros1_mcap) = (
        repo("datasets/logs/containers/husky_10s_bz2.bag"),
        repo("datasets/logs/containers/husky_10s_sqlite3"),
        repo("datasets/logs/containers/husky_10s_ros1.mcap"),
    );
    let set = format!(
        r#"agents = [2]
seeds = [3]
logs = [{{ path = "{bag}", rate = "max" }}, {{ path = "{sqlite}", rate = "max" }}]
[payload]
sizes = [16]
rate_hz = 200
count = 3
agents = 2
transport = "inproc"
[faults]
agents = 2
transports = ["inproc"]
log = {{ path = "{ros1_mcap}", rate = "max" }}
variants = [{{ label = "no faults" }}]
[partition]
agents = 2
partition_ms = 50
rate_hz = 100
announce_ms = 50
repetitions = 1
transports = ["inproc"]
"#
    );
    let (out, _) = run_report("containers", &set);
    let results: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let datasets = results["provenance"]["datasets"].as_array().unwrap();
    assert_eq!(datasets.len(), 3, "{datasets:?}");
    assert!(datasets.iter().all(|d| d["sha256"] == d["manifest_sha256"]), "{datasets:?}");
    let _ = std::fs::remove_dir_all(out.parent().unwrap());
}
