//! `cortex check` from the command line: a small convergence check passes with a complete JSON report, bad
//! arguments are refused with a message, and a build without the `mutants` feature refuses to plant bugs.

use std::process::Command;

fn cortex(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cortex")).args(args).output().expect("cortex runs")
}

#[test]
fn small_convergence_check_passes_with_a_json_report() {
    let out = cortex(&["check", "convergence", "--replicas", "2", "--ops", "2", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON report");
    assert_eq!(report["model"], "convergence");
    assert_eq!(report["complete"], true);
    assert!(report["unique_states"].as_u64().unwrap() > 100);
    let properties = report["properties"].as_array().unwrap();
    assert!(properties.iter().all(|p| p["holds"] == true));
}

#[test]
fn scheduler_check_passes() {
    let out = cortex(&["check", "scheduler", "--horizon-ns", "30"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("shared dependency runs once per period"));
}

#[test]
fn bad_arguments_are_refused_with_a_message() {
    let out = cortex(&["check", "convergence", "--network", "carrier-pigeon"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown network"));
    let out = cortex(&["check", "convergence", "--replicas", "9"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--replicas must be between 2 and 5"));
}

#[cfg(not(feature = "mutants"))]
#[test]
fn a_normal_build_cannot_plant_mutants() {
    let out = cortex(&["check", "mutants"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--features mutants"));
}

#[test]
fn explorer_serves_the_model_and_a_busy_address_is_an_error() {
    use std::io::{Read, Write};
    use std::net::{TcpListener, TcpStream};
    use std::time::{Duration, Instant};

    // A busy address: a clear error, not Stateright's panic.
    let busy = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = busy.local_addr().unwrap().to_string();
    let out = cortex(&["check", "scheduler", "--explore", &address]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot listen"), "{}", String::from_utf8_lossy(&out.stderr));
    drop(busy);

    // A free address: the Explorer answers over HTTP.
    let mut child = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["check", "scheduler", "--explore", &address])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let response = loop {
        if let Ok(mut stream) = TcpStream::connect(&address) {
            stream.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
            stream.write_all(b"GET /.states HTTP/1.0\r\n\r\n").unwrap();
            let mut response = String::new();
            let _ = stream.read_to_string(&mut response);
            break response;
        }
        assert!(Instant::now() < deadline, "the Explorer never listened on {address}");
        std::thread::sleep(Duration::from_millis(50));
    };
    child.kill().unwrap();
    let _ = child.wait();
    assert!(response.starts_with("HTTP/1.1 200") || response.starts_with("HTTP/1.0 200"), "{response}");
    assert!(response.contains("planner"), "the initial state names the model's components: {response}");
}
