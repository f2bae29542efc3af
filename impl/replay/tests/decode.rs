//! Tests of the ROS 2 decoders and the bridge on real messages of the bundled logs. Expected values were read
//! independently with the Python `mcap-ros2-support` decoder (see `datasets/logs/README.md`).

// The expected f32 values are written as Python printed them (the shortest f64 that rounds to them).
#![allow(clippy::excessive_precision)]

use std::path::Path;
use std::sync::Arc;

use bytes::Bytes;
use dsr::{Replica, ReplicaId, Value, attrs};
use replay::log::{Log, Message, ReadOptions};
use replay::ros2::{self, Ros2Message};
use replay::{Bridge, BridgeOptions};

fn open(name: &str) -> Log {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs").join(name);
    Log::open(path, ReadOptions::default()).unwrap()
}

fn first<'a>(log: &'a Log, topic: &str) -> &'a Message {
    log.messages.iter().find(|m| m.channel.topic == topic).unwrap()
}

fn decode(message: &Message) -> Ros2Message {
    ros2::decode(message.channel.type_name(), &message.data).unwrap().unwrap()
}

#[test]
fn euroc_image_camera_info_imu_pose_tf() {
    let log = open("euroc_v1_01_easy_cam0_1s.mcap");
    let Ros2Message::Image(image) = decode(first(&log, "/cam0/image_raw")) else { panic!() };
    assert_eq!((image.width, image.height, image.step, image.encoding.as_str()), (752, 480, 752, "mono8"));
    assert_eq!(
        (image.header.frame_id.as_str(), image.header.sec, image.header.nanosec),
        ("cam0", 1403715273, 262142976)
    );
    assert_eq!(image.data.len(), 360_960);
    assert_eq!((&image.data[..4], image.data[1000]), (&[77u8, 80, 80, 81][..], 145));
    // The pixels are a view of the message, not a copy.
    let message = first(&log, "/cam0/image_raw");
    let range = message.data.as_ptr() as usize..message.data.as_ptr() as usize + message.data.len();
    assert!(range.contains(&(image.data.as_ptr() as usize)));

    let Ros2Message::CameraInfo(info) = decode(first(&log, "/cam0/camera_info")) else { panic!() };
    assert_eq!((info.width, info.height, info.distortion_model.as_str()), (752, 480, "plumb_bob"));
    assert_eq!(info.k, [458.654, 0.0, 367.215, 0.0, 457.296, 248.375, 0.0, 0.0, 1.0]);
    assert_eq!(info.d, [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0]);

    let Ros2Message::Imu(imu) = decode(first(&log, "/imu0")) else { panic!() };
    assert_eq!(imu.header.frame_id, "imu0");
    assert_eq!(imu.angular_velocity, [-0.0020943951023931952, 0.017453292519943295, 0.07749261878854824]);
    assert_eq!(imu.linear_acceleration, [9.087495666666666, 0.13075533333333333, -3.693838166666666]);
    assert_eq!(imu.orientation, [0.0, 0.0, 0.0, 1.0]);

    let Ros2Message::PoseStamped(pose) = decode(first(&log, "/ground_truth/pose")) else { panic!() };
    assert_eq!(pose.header.frame_id, "world");
    assert_eq!(pose.pose.position, [0.878973, 2.18348, 0.948329]);
    assert_eq!(pose.pose.orientation, [-0.824253, -0.106951, -0.551676, 0.069437]);

    let Ros2Message::Tf(transforms) = decode(first(&log, "/tf_static")) else { panic!() };
    let pairs: Vec<_> = transforms.iter().map(|t| (t.header.frame_id.as_str(), t.child_frame_id.as_str())).collect();
    assert_eq!(pairs, [("body", "cam0"), ("body", "cam1"), ("body", "imu0")]);
    assert_eq!(transforms[0].translation, [-0.0216401454975, -0.064676986768, 0.00981073058949]);
    assert_eq!(
        transforms[0].rotation,
        [-0.007707179755538301, 0.010499323370588468, 0.7017528002920512, 0.7123014606690344]
    );
}

#[test]
fn ouster_cloud() {
    let log = open("ouster_os1-128_1scan.mcap");
    let Ros2Message::PointCloud2(cloud) = decode(first(&log, "/ouster/points")) else { panic!() };
    assert_eq!((cloud.height, cloud.width, cloud.point_step, cloud.row_step), (128, 1024, 32, 32768));
    assert_eq!(cloud.header.frame_id, "os_sensor");
    let names: Vec<_> = cloud.fields.iter().map(|f| (f.name.as_str(), f.offset, f.datatype)).collect();
    assert_eq!(&names[..4], [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7)]);
    let columns = cloud.columns(1000.0).unwrap();
    assert_eq!(columns.x.len(), 131_072);
    let returns = (0..columns.x.len()).filter(|&i| columns.x[i] != 0.0 || columns.y[i] != 0.0 || columns.z[i] != 0.0);
    assert_eq!(returns.count(), 107_647);
    assert_eq!(
        (columns.x[72], columns.y[72], columns.z[72]),
        (-39.39814758300781 * 1000.0, 22.309494018554688 * 1000.0, 17.364704132080078 * 1000.0)
    );
    let i = 65 * 1024 + 512;
    assert_eq!(columns.x[i], 74.15015411376953 * 1000.0);
    assert_eq!(columns.intensity.unwrap()[i], 27.0);
    // The raw packets are of a type the decoders do not know.
    assert_eq!(ros2::decode(first(&log, "/ouster/lidar_packets").channel.type_name(), &Bytes::new()), Ok(None));
}

#[test]
fn sick_scan_and_husky_fix_and_odometry() {
    let log = open("sick_tim7xx_scan_10s.mcap");
    let Ros2Message::LaserScan(scan) = decode(first(&log, "/scan")) else { panic!() };
    assert_eq!(scan.header.frame_id, "laser");
    assert_eq!((scan.angle_min, scan.angle_max), (-2.356194496154785, 2.3557231426239014));
    assert_eq!(
        (scan.angle_increment, scan.range_min, scan.range_max),
        (0.00581718236207962, 0.05000000074505806, 64.0)
    );
    assert_eq!((scan.ranges.len(), scan.intensities.len()), (811, 811));
    assert_eq!(
        (scan.ranges[0], scan.ranges[400], scan.intensities[400]),
        (0.6260000467300415, 1.2660000324249268, 13477.0)
    );

    let log = open("husky_gps_imu_odom_robot_localization_test1.mcap");
    let Ros2Message::NavSatFix(fix) = decode(first(&log, "/fix")) else { panic!() };
    assert_eq!(fix.header.frame_id, "/gps");
    assert_eq!(
        (fix.latitude, fix.longitude, fix.altitude, fix.status),
        (42.375812, -71.14739466666667, 7.299999999999997, 1)
    );
    let Ros2Message::Odometry(odometry) = decode(first(&log, "/husky_velocity_controller/odom")) else { panic!() };
    assert_eq!((odometry.header.frame_id.as_str(), odometry.child_frame_id.as_str()), ("odom", "base_link"));
    assert_eq!(odometry.pose.position, [8.251562792367952, -0.30489320435155026, 0.0]);
    assert_eq!(odometry.pose.orientation, [0.0, 0.0, -0.1359940102210928, 0.9907096593775521]);
    assert_eq!((odometry.linear[0], odometry.angular[2]), (0.17779841518092315, 0.00085541027636822));
}

#[test]
fn every_prefix_of_a_real_payload_is_an_error_not_a_panic() {
    for (file, topic) in [
        ("sick_tim7xx_scan_10s.mcap", "/scan"),
        ("sick_tim7xx_scan_10s.mcap", "/cloud"),
        ("euroc_v1_01_easy_cam0_1s.mcap", "/tf_static"),
        ("euroc_v1_01_easy_cam0_1s.mcap", "/cam0/camera_info"),
        ("husky_gps_imu_odom_robot_localization_test1.mcap", "/husky_velocity_controller/odom"),
        ("husky_gps_imu_odom_robot_localization_test1.mcap", "/fix"),
        ("husky_gps_imu_odom_robot_localization_test1.mcap", "/imu/data"),
    ] {
        let log = open(file);
        let message = first(&log, topic);
        for len in 0..message.data.len() {
            let error = ros2::decode(message.channel.type_name(), &message.data.slice(..len)).unwrap_err();
            // The offset is where the field starts, after alignment padding (at most 7 bytes past the end).
            assert!(error.offset <= len + 7, "{error}");
        }
    }
    let error = ros2::decode("sensor_msgs/msg/Imu", &Bytes::from_static(&[0, 1, 0, 0, 1, 2])).unwrap_err();
    assert_eq!(error.to_string(), "sensor_msgs/msg/Imu: field `header.stamp.sec` at byte 4: needs 4 bytes, 2 left");
    let error = ros2::decode("sensor_msgs/msg/Imu", &Bytes::from_static(&[0, 7, 0, 0])).unwrap_err();
    assert_eq!(error.field, "encapsulation");
}

#[test]
fn big_endian_cdr_decodes() {
    // geometry_msgs/PoseStamped, big-endian: stamp 1 s 2 ns, frame "m", position (1, 2, 3), orientation (0, 0, 0, 1).
    let mut data = vec![0, 0, 0, 0];
    data.extend(1i32.to_be_bytes());
    data.extend(2u32.to_be_bytes());
    data.extend(2u32.to_be_bytes());
    data.extend(b"m\0");
    data.extend([0; 2]); // align to 8 counted from the end of the encapsulation header (18 -> 20)
    for value in [1.0f64, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
        data.extend(value.to_be_bytes());
    }
    let Some(Ros2Message::PoseStamped(pose)) = ros2::decode("geometry_msgs/PoseStamped", &Bytes::from(data)).unwrap()
    else {
        panic!()
    };
    assert_eq!((pose.header.stamp_ns(), pose.header.frame_id.as_str()), (1_000_000_002, "m"));
    assert_eq!((pose.pose.position, pose.pose.orientation), ([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]));
}

fn bridge_replica() -> Replica {
    Replica::with_dictionary(ReplicaId(1), replay::bridge::dictionary().unwrap())
}

fn ingest_all(log: &Log, options: BridgeOptions) -> (Bridge, Replica) {
    let mut bridge = Bridge::new(options);
    let mut replica = bridge_replica();
    for message in &log.messages {
        bridge.ingest(&mut replica, message.log_time, message, 0);
    }
    (bridge, replica)
}

#[test]
fn bridge_writes_euroc_into_the_graph() {
    let log = open("euroc_v1_01_easy_cam0_1s.mcap");
    let (bridge, replica) = ingest_all(&log, BridgeOptions::default());
    let stats = bridge.stats();
    assert_eq!(stats.error_count(), 0, "{:?}", stats.first_errors);
    assert_eq!(stats.decoded.values().sum::<u64>(), log.messages.len() as u64);
    assert!(stats.unknown.is_empty());
    let camera = replica.node(bridge.topic_node("/cam0/image_raw").unwrap()).unwrap();
    assert_eq!(camera.node_type(), "camera");
    assert_eq!(camera.get(attrs::CAM_RGB_WIDTH), Some(752));
    assert_eq!(camera.get(attrs::CAM_RGB_DEPTH), Some(1));
    let last = log.messages.iter().rfind(|m| m.channel.topic == "/cam0/image_raw").unwrap();
    let Some(Value::Bytes(pixels)) = camera.attr("cam_rgb") else { panic!() };
    assert_eq!(pixels.len(), 360_960);
    assert_eq!(&pixels[..], &last.data[last.data.len() - 360_960..], "the last frame's pixels");
    let frames = log.messages.iter().filter(|m| m.channel.topic == "/cam0/image_raw").count() as u64;
    assert_eq!(camera.get(attrs::SEQUENCE), Some(frames - 1));
    // TF: world -> body -> cam0 -> the camera topic; cam0 sits 21.6 mm, 64.7 mm, 9.8 mm from the body.
    let world = bridge.frame_node("world").unwrap();
    let body = bridge.frame_node("body").unwrap();
    let cam0 = bridge.frame_node("cam0").unwrap();
    assert_eq!(replica.rt_parent_edge(cam0).unwrap().unwrap().from(), body);
    assert_eq!(replica.rt_parent_edge(camera.id()).unwrap().unwrap().from(), cam0);
    let p = replica.transform_point(cam0, body, [0.0, 0.0, 0.0]).unwrap();
    for (got, want) in p.iter().zip([-21.6401454975, -64.676986768, 9.81073058949]) {
        assert!((got - want).abs() < 1e-3, "{p:?}");
    }
    // A point 1 m along the camera's z axis, checked against the quaternion rotation computed here.
    let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        0.7123014606690344,
        -0.007707179755538301,
        0.010499323370588468,
        0.7017528002920512,
    ));
    let want = q * nalgebra::Vector3::new(0.0, 0.0, 1000.0);
    let got = replica.transform_point(cam0, body, [0.0, 0.0, 1000.0]).unwrap();
    for (i, want) in [want.x - 21.6401454975, want.y - 64.676986768, want.z + 9.81073058949].into_iter().enumerate() {
        assert!((got[i] - want).abs() < 1e-2, "{got:?} vs {want}");
    }
    // The body's pose is the last ground-truth pose, in mm.
    let last_tf = log.messages.iter().rfind(|m| m.channel.topic == "/tf").unwrap();
    let Ros2Message::Tf(transforms) = decode(last_tf) else { panic!() };
    let origin = replica.transform_point(body, world, [0.0, 0.0, 0.0]).unwrap();
    for (got, want) in origin.iter().zip(transforms[0].translation) {
        assert!((got - want * 1000.0).abs() < 1e-2, "{origin:?}");
    }
    replica.check_invariants().unwrap();
}

#[test]
fn bridge_laser_cloud_gps_odometry_and_opaque() {
    let (bridge, replica) = ingest_all(&open("sick_tim7xx_scan_10s.mcap"), BridgeOptions::default());
    let laser = replica.node(bridge.topic_node("/scan").unwrap()).unwrap();
    let Some(dists) = laser.get(attrs::LASER_DISTS) else { panic!() };
    let Some(angles) = laser.get(attrs::LASER_ANGLES) else { panic!() };
    assert_eq!((dists.len(), angles.len()), (811, 811));
    assert!((angles[0] - -2.356194496154785).abs() < 1e-6 && (angles[810] - 2.3557231).abs() < 1e-4, "{}", angles[810]);
    assert!(dists.iter().all(|d| d.is_nan() || (*d >= 0.0 && *d <= 64_000.0)));
    let cloud = replica.node(bridge.topic_node("/cloud").unwrap()).unwrap();
    assert_eq!(cloud.get(attrs::LIDAR_POINTS_X).unwrap().len(), 811);

    let (bridge, replica) =
        ingest_all(&open("husky_gps_imu_odom_robot_localization_test1.mcap"), BridgeOptions::default());
    assert_eq!(bridge.stats().decoded["sensor_msgs/msg/NavSatFix"], 989);
    let gps = replica.node(bridge.topic_node("/fix").unwrap()).unwrap();
    assert_eq!(gps.node_type(), "gps");
    assert!(gps.get(attrs::GPS_LATITUDE).is_some_and(|lat| (42.0..43.0).contains(&lat)));
    let odometry = replica.node(bridge.topic_node("/husky_velocity_controller/odom").unwrap()).unwrap();
    assert_eq!(odometry.get(attrs::SEQUENCE), Some(3951));
    assert!(odometry.get(attrs::POSE_TRANSLATION).is_some());

    // Types without a decoder: decoded from the definitions the file carries by default, carried as opaque bytes
    // when asked.
    let log = open("ouster_os1-128_1scan.mcap");
    let (bridge, replica) = ingest_all(&log, BridgeOptions::default());
    assert_eq!(bridge.stats().described["ouster_sensor_msgs/msg/PacketMsg"], 18);
    assert_eq!(bridge.stats().described["std_msgs/msg/String"], 1);
    assert!(bridge.stats().unknown.is_empty() && bridge.stats().error_count() == 0, "{:?}", bridge.stats());
    let metadata = replica.node(bridge.topic_node("/ouster/metadata").unwrap()).unwrap();
    let Some(Value::String(json)) = metadata.attr("String.data") else { panic!() };
    assert!(json.starts_with('{'), "the sensor's JSON metadata");
    let packets = replica.node(bridge.topic_node("/ouster/lidar_packets").unwrap()).unwrap();
    assert!(matches!(packets.attr("PacketMsg.buf"), Some(Value::Bytes(buf)) if buf.len() > 1000));
    let (bridge, replica) = ingest_all(&log, BridgeOptions { opaque: true, topics: None });
    assert_eq!(bridge.stats().unknown["ouster_sensor_msgs/msg/PacketMsg"], 18);
    assert_eq!(bridge.stats().opaque, 19);
    let metadata = replica.node(bridge.topic_node("/ouster/metadata").unwrap()).unwrap();
    let Some(Value::Bytes(payload)) = metadata.attr(replay::bridge::OPAQUE_PAYLOAD) else { panic!() };
    assert_eq!(payload, &first(&log, "/ouster/metadata").data);
    assert_eq!(metadata.attr(replay::bridge::OPAQUE_TYPE), Some(&Value::String(Arc::from("std_msgs/msg/String"))));

    // Topic selection.
    let (bridge, _) = ingest_all(&log, BridgeOptions { opaque: false, topics: Some(vec!["/ouster/points".into()]) });
    assert_eq!((bridge.stats().filtered, bridge.stats().decoded.values().sum::<u64>()), (18 + 1, 1));
}
