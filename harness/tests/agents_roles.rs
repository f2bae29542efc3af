//! Role processes over RTPS on loopback: one `cortex agent --role fixture-camera` writes real EuRoC frames into the
//! `cam_rgb` of camera node `cam0`; one `cortex agent --role camera-detector` reads them from its own replica,
//! detects bright blobs and writes `blob` nodes under the camera, which must appear in the first agent's graph.
//! The detector's runtime is then called from this test through an agent of its own: its components with
//! statistics, a role method and the latest debug frame come back over the `Calls` channel. Last, `cortex inspect
//! --debug-agent 2` serves the detector's components and primitives in its Debug view's JSON.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId, CallError, StatusLine};
use bica::debug::DebugFrame;
use bica::service::{COMPONENTS, ComponentsReply, DEBUG_FRAME};
use transport::SystemClock;
use transport::rtps::{RtpsConfig, RtpsTransport};

/// Visible nodes of `node_type` in a status line.
fn count(status: &StatusLine, node_type: &str) -> u64 {
    status.node_types.as_ref().and_then(|types| types.get(node_type)).copied().unwrap_or(0)
}

/// A spawned agent whose status lines arrive on a channel; killed when dropped.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn spawn(id: u32, prefix: &str, extra: &[&str], tx: mpsc::Sender<(u32, StatusLine)>) -> Proc {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["agent", "--id", &id.to_string(), "--domain", "0", "--topic-prefix", prefix, "--json-status"])
        // A graph of this test alone: no incarnation record left in the home directory.
        .args(["--state-dir", "none"])
        .args(["--status-ms", "100"])
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("cortex agent starts");
    let stdout = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if !line.starts_with('{') {
                continue;
            }
            let status: StatusLine = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
            if tx.send((id, status)).is_err() {
                return;
            }
        }
    });
    Proc(child)
}

#[test]
fn a_camera_detector_process_writes_blob_nodes_into_the_camera_agents_graph() {
    let prefix = format!("roles{}", std::process::id());
    let (tx, rx) = mpsc::channel();
    let _camera = spawn(1, &prefix, &["--role", "fixture-camera", "--join-wait-ms", "500"], tx.clone());
    let _detector = spawn(2, &prefix, &["--role", "camera-detector", "--join-wait-ms", "60000"], tx);

    // The detector's blob nodes reach the camera agent (bounded wait).
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut seen_detector = false;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let (id, status) = rx.recv_timeout(left).expect("no blob node reached agent 1 within 60 s");
        seen_detector |= id == 2 && status.ready;
        if id == 1 && count(&status, "blob") > 0 {
            assert!(seen_detector, "blob nodes appeared before the detector was ready");
            assert_eq!(count(&status, "camera"), 1);
            break;
        }
    }

    // The detector's runtime, called from another agent.
    let rtps = RtpsConfig { domain_id: 0, topic_prefix: prefix.clone(), ..RtpsConfig::default() };
    let config = AgentConfig { join_wait: Duration::from_secs(30), ..AgentConfig::new(AgentId(9)) };
    let caller = Agent::start(config, RtpsTransport::new(rtps).unwrap(), Arc::new(SystemClock)).unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let components: ComponentsReply = loop {
        match caller.call(AgentId(2), COMPONENTS, &(), Duration::from_millis(500)) {
            Ok(reply) => break reply,
            Err(CallError::Timeout { .. }) if Instant::now() < deadline => {}
            Err(error) => panic!("calling the detector: {error}"),
        }
    };
    let names: Vec<&str> = components.statistics.components.iter().map(|c| c.name.as_str()).collect();
    for expected in ["Camera", "ColourLabeller", "BlobDetector", "DebugCollector"] {
        assert!(names.iter().any(|n| n.contains(expected)), "{expected} missing from {names:?}");
    }
    let detector = components.statistics.components.iter().find(|c| c.name.ends_with("BlobDetector")).unwrap();
    assert!(detector.active && detector.counters.runs > 0, "{detector:?}");
    assert_eq!(components.marked.len(), 2, "labeller and detector are marked: {:?}", components.marked);
    let blobs: u64 = caller.call(AgentId(2), "BlobDetector.blob_count", &(), Duration::from_secs(5)).unwrap();
    assert!(blobs > 0);
    let frame: DebugFrame = caller.call(AgentId(2), DEBUG_FRAME, &(), Duration::from_secs(5)).unwrap();
    assert!(!frame.entries.is_empty(), "the debug frame has the labelled image and blob primitives");
    let unknown = caller.call::<(), ()>(AgentId(1), "BlobDetector.blob_count", &(), Duration::from_secs(5));
    assert!(matches!(unknown, Err(CallError::UnknownMethod { .. })), "{unknown:?}");
    caller.shutdown();

    // The inspector's Debug view of the detector process.
    let mut inspect = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["inspect", "--id", "10", "--domain", "0", "--topic-prefix", &prefix, "--listen", "127.0.0.1:0"])
        .args(["--debug-agent", "2", "--join-wait-ms", "30000"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("cortex inspect starts");
    let mut line = String::new();
    BufReader::new(inspect.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let _inspect = Proc(inspect);
    let addr = line.split("http://").nth(1).and_then(|rest| rest.split_whitespace().next()).expect(&line).to_owned();
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let debug = get_json(&addr, "/api/debug");
        assert_eq!(debug["available"], true, "{debug}");
        let listed = debug["components"].as_array().cloned().unwrap_or_default();
        let entries = debug["frame"]["entries"].as_array().map_or(0, Vec::len);
        if listed.iter().any(|c| c["name"].as_str().is_some_and(|n| n.ends_with("BlobDetector"))) && entries > 0 {
            assert!(listed.iter().any(|c| c["marked"] == true), "{debug}");
            break;
        }
        assert!(Instant::now() < deadline, "the Debug view never showed the detector: {debug}");
        std::thread::sleep(Duration::from_millis(300));
    }
}

/// One GET on the inspector's HTTP server, the body parsed as JSON.
fn get_json(addr: &str, path: &str) -> serde_json::Value {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).unwrap();
    let body = response.split_once("\r\n\r\n").map(|(_, body)| body).expect(&response);
    serde_json::from_str(body).unwrap_or_else(|e| panic!("{path}: {e}: {body}"))
}

/// The `bridge` role: one process replays the bundled EuRoC cut (camera, IMU, pose, TF) into its graph through the
/// replay bridge; a plain agent process receives the sensor nodes and the camera images over RTPS.
#[test]
fn a_bridge_process_replays_a_log_into_another_agents_graph() {
    let prefix = format!("bridge{}", std::process::id());
    let log = concat!(env!("CARGO_MANIFEST_DIR"), "/../datasets/logs/euroc_v1_01_easy_cam0_1s.mcap");
    let (tx, rx) = mpsc::channel();
    let bridge_args = ["--role", "bridge", "--log", log, "--rate", "max", "--loops", "3", "--join-wait-ms", "500"];
    let _bridge = spawn(1, &prefix, &bridge_args, tx.clone());
    let _receiver = spawn(2, &prefix, &["--join-wait-ms", "60000"], tx);

    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let (id, status) = rx.recv_timeout(left).expect("the bridged sensors never reached agent 2 within 60 s");
        let count = |node_type: &str| count(&status, node_type);
        if id == 2 && count("camera") >= 2 && count("imu") >= 1 && count("pose") >= 1 {
            // Camera images and camera info are two topics, hence two camera nodes; TF frames are transforms.
            assert!(count("transform") >= 1, "TF frames arrive as transform nodes: {status:?}");
            break;
        }
    }
}
