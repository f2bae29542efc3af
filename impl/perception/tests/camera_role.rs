//! The camera-detector role on real EuRoC frames: labelled images, blobs, and `blob` nodes under the camera
//! node once tracks are confirmed; a malformed image is skipped with a warning.

use bica::prelude::*;
use dsr::{NewNode, Replica, ReplicaId, Value, attrs};
use perception::blobs::{BlobConfig, BlobDetector, find_blobs};
use perception::fixtures;
use perception::graph::{self, share_replica};
use perception::labelling::{ColourClass, ColourLabeller, LabelConfig, LabelTables};
use perception::roles;
use perception::sensors::{CameraReader, write_image};

#[test]
fn camera_detector_role_turns_bright_regions_of_real_frames_into_blob_nodes() {
    let (replica, graph) = share_replica(Replica::new(ReplicaId(2)));
    let camera = graph.borrow_mut().insert_node(1, NewNode::new("camera", "cam0")).unwrap();
    let tables = LabelTables::new(LabelConfig {
        classes: vec![ColourClass { name: "bright".into(), min: [200; 3], max: [255; 3], display: [255, 255, 0] }],
    })
    .unwrap();
    let mut runtime = Runtime::new(RuntimeConfig::default(), VirtualClock::new(0));
    let config = BlobConfig { min_area_px: 200, ..BlobConfig::default() };
    roles::camera_detector(&mut runtime, graph.clone(), "cam0", tables.clone(), config, 50).unwrap();
    let frame = fixtures::euroc_frames().unwrap().remove(0);
    let expected = find_blobs(&tables.label(&frame), 200);
    assert!(!expected.is_empty(), "the frame has bright regions");
    let mut now = 1_000_000u64;
    for sequence in 0..4u64 {
        // The same frame re-sent: the blobs stay put, so their tracks get confirmed.
        write_image(&mut *graph.borrow_mut(), now, camera, &frame, now, sequence).unwrap();
        now += 50_000_000;
        runtime.run_until(now).unwrap();
    }
    assert_eq!(runtime.registry().get::<ColourLabeller>().unwrap().frames(), 4);
    let detector = runtime.registry().get::<BlobDetector>().unwrap();
    assert_eq!(detector.blobs(), &expected[..]);
    let r = replica.borrow();
    let blob_nodes: Vec<_> = r.nodes().filter(|n| n.node_type() == "blob").collect();
    assert_eq!(blob_nodes.len(), expected.len());
    for node in &blob_nodes {
        assert_eq!(r.rt_parent_edge(node.id()).unwrap().unwrap().from(), camera);
        assert_eq!(node.get(graph::attrs::BLOB_CLASS), Some(0));
        assert!(node.get(graph::attrs::BLOB_AREA_PX).unwrap() >= 200);
    }
    drop(r);
    // A malformed image (width disagrees with the bytes): warned and skipped, nothing fails.
    graph.borrow_mut().set_node_attrs(now, camera, vec![(attrs::CAM_RGB_WIDTH.name(), Value::I32(751))]).unwrap();
    runtime.run_until(now + 50_000_000).unwrap();
    assert_eq!(runtime.registry().get::<CameraReader>().unwrap().malformed(), 1);
    assert_eq!(runtime.registry().get::<ColourLabeller>().unwrap().frames(), 4);
    assert_eq!(runtime.step_failures(), 0);
}
