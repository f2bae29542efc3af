//! The example bridge file under `experiments/` is a valid bridge file (the README points to it).

use std::path::Path;

use ros2bridge::BridgeConfig;

#[test]
fn the_example_bridge_file_reads() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/ros2_bridge.toml");
    let config = BridgeConfig::load(&path).unwrap();
    assert_eq!(config.inputs.len(), 4);
    assert_eq!(config.inputs[1].node.as_deref(), Some("camera"));
    assert_eq!((config.image_out.len(), config.laser_out.len()), (1, 1));
    assert!(config.tf_out.is_none());
}
