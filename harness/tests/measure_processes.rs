//! Measured runs whose receivers are separate `cortex measure-receiver` processes over RTPS on loopback.

use std::path::PathBuf;

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
