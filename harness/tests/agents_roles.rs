//! Role processes over RTPS on loopback: one `cortex agent --role fixture-camera` writes real EuRoC frames into the
//! `cam_rgb` of camera node `cam0`; one `cortex agent --role camera-detector` reads them from its own replica,
//! detects bright blobs and writes `blob` nodes under the camera, which must appear in the first agent's graph.
//! The detector's runtime is then called from this test through an agent of its own: its components with
//! statistics, a role method and the latest debug frame come back over the `Calls` channel.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId, CallError};
use bica::debug::DebugFrame;
use bica::service::{COMPONENTS, ComponentsReply, DEBUG_FRAME};
use transport::SystemClock;
use transport::rtps::{RtpsConfig, RtpsTransport};

/// A spawned agent whose status lines arrive on a channel; killed when dropped.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn spawn(id: u32, prefix: &str, extra: &[&str], tx: mpsc::Sender<(u32, serde_json::Value)>) -> Proc {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cortex"))
        .args(["agent", "--id", &id.to_string(), "--domain", "0", "--topic-prefix", prefix, "--json-status"])
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
            if let Ok(value) = serde_json::from_str(&line)
                && tx.send((id, value)).is_err()
            {
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
        seen_detector |= id == 2 && status["ready"] == true;
        let blobs = status["node_types"]["blob"].as_u64().unwrap_or(0);
        if id == 1 && blobs > 0 {
            assert!(seen_detector, "blob nodes appeared before the detector was ready");
            assert_eq!(status["node_types"]["camera"].as_u64(), Some(1));
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
}
