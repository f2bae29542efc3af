//! Measured runs whose receivers are separate `cortex measure-receiver` processes over RTPS on loopback.

use std::path::{Path, PathBuf};
use std::time::Duration;

use measure::run::{Link, RunConfig, run};
use measure::workload::synthetic;
use transport::fault::FaultConfig;

fn config(agents: u32, domain_id: u16) -> RunConfig {
    RunConfig {
        agents,
        link: Link::Processes { domain_id },
        receiver_program: Some(PathBuf::from(env!("CARGO_BIN_EXE_cortex"))),
        ..RunConfig::default()
    }
}

#[test]
fn receiver_processes_apply_every_write_and_end_with_the_sources_digest() {
    let workload = synthetic(4096, 200.0, 30, 3).unwrap();
    let result = run(&workload, &config(3, 73)).unwrap();
    assert_eq!(result.transport, "rtps-processes");
    assert_eq!(result.writes, 31);
    assert_eq!(result.writes_not_everywhere, 0, "{result:?}");
    assert_eq!(result.latency.count, 31 * 2);
    assert!(result.digests_equal && result.end_convergence_ns.is_some());
    assert_eq!(result.refused, 0);
    assert_eq!(result.bandwidth.received_bytes, vec![result.sample_bytes; 2]);
    let kinds: Vec<_> = result.agent_costs.iter().map(|c| (c.agent, c.kind)).collect();
    assert_eq!(kinds, vec![(1, "thread"), (2, "process"), (3, "process")]);
    for cost in &result.agent_costs[1..] {
        assert!(cost.cpu_ns.is_some_and(|ns| ns > 0), "{cost:?}");
        assert!(cost.peak_rss_bytes.is_some_and(|b| b > 1 << 20), "{cost:?}");
    }
}

#[test]
fn faults_injected_in_receiver_processes_are_counted_and_still_converge() {
    let workload = synthetic(64, 500.0, 100, 4).unwrap();
    let faults = FaultConfig { duplicate: 0.2, reorder: 0.3, reorder_ns: 3_000_000, ..FaultConfig::default() };
    let result = run(&workload, &RunConfig { faults: Some(faults), ..config(2, 74) }).unwrap();
    assert_eq!(result.transport, "rtps-processes+faults");
    assert_eq!(result.writes_not_everywhere, 0, "{result:?}");
    assert!(result.digests_equal);
    assert!(result.bandwidth.injected_duplicates > 0);
}

#[test]
fn a_missing_receiver_program_is_an_error_not_a_hang() {
    let workload = synthetic(16, 100.0, 2, 1).unwrap();
    let mut config = config(2, 75);
    config.receiver_program = Some(PathBuf::from("/nonexistent/cortex"));
    let error = run(&workload, &config).unwrap_err();
    assert!(format!("{error:#}").contains("cannot start the receiver process"), "{error:#}");
    config.receiver_program = None;
    let error = run(&workload, &config).unwrap_err();
    assert!(format!("{error:#}").contains("receiver program"), "{error:#}");
}

/// A receiver program for one-receiver runs that, on each of its first `silent` starts, stays alive without ever
/// answering (as a receiver whose discovery never completes does), and runs `cortex measure-receiver` after that.
/// Each start adds a line to `dir/starts`.
fn silent_then_real(dir: &Path, silent: u32) -> PathBuf {
    let starts = dir.join("starts");
    let script = dir.join("receiver.sh");
    let body = format!(
        "#!/bin/sh\nn=$(cat '{starts}' 2>/dev/null | wc -l)\necho start >> '{starts}'\n\
         if [ \"$n\" -lt {silent} ]; then exec sleep 60; fi\nexec '{cortex}' \"$@\"\n",
        starts = starts.display(),
        cortex = env!("CARGO_BIN_EXE_cortex"),
    );
    std::fs::write(&script, body).unwrap();
    let mut permissions = std::fs::metadata(&script).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut permissions, 0o755);
    std::fs::set_permissions(&script, permissions).unwrap();
    script
}

fn starts(dir: &Path) -> usize {
    std::fs::read_to_string(dir.join("starts")).map(|text| text.lines().count()).unwrap_or(0)
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("measure-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_receiver_that_never_answers_the_probes_is_started_again_and_the_run_says_so() {
    let dir = scratch("restart");
    let workload = synthetic(64, 200.0, 10, 2).unwrap();
    let mut config = config(2, 76);
    config.receiver_program = Some(silent_then_real(&dir, 1));
    // Long enough for the real receiver's discovery on a loaded CI machine; the silent first start waits it out.
    config.probe_window = Duration::from_secs(5);
    let result = run(&workload, &config).unwrap();
    // At least the silent start and one more (a real start whose discovery stalls may itself be started again).
    assert!(result.start_attempts >= 2, "{}", result.start_attempts);
    assert_eq!(starts(&dir), result.start_attempts as usize);
    assert!(result.digests_equal && result.writes_not_everywhere == 0, "{result:?}");
    let json = serde_json::to_value(&result).unwrap();
    assert_eq!(json["start_attempts"], result.start_attempts, "a restarted run says so in results.json");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn receivers_that_never_answer_fail_the_run_after_the_last_start_and_are_named() {
    let dir = scratch("silent");
    let workload = synthetic(64, 200.0, 10, 2).unwrap();
    let mut config = config(2, 77);
    config.receiver_program = Some(silent_then_real(&dir, u32::MAX));
    config.probe_window = Duration::from_millis(300);
    let error = format!("{:#}", run(&workload, &config).unwrap_err());
    assert!(error.contains("0 of 1 receiver processes answered") && error.contains("replicas [2]"), "{error}");
    assert_eq!(starts(&dir), measure::restart::MAX_STARTS as usize);
    let _ = std::fs::remove_dir_all(&dir);
}
