"""`cortex bridge ros2` against another vendor's DDS: Eclipse Cyclone DDS (its Python binding) plays the ROS 2 side on
loopback. Cyclone publishes ROS 2-shaped LaserScan, Image and TFMessage samples (sensor, default and /tf_static QoS)
that the bridge must write into the graph; Cyclone subscribes to what the bridge publishes (/tf, /tf_static with a
late-joining transient-local subscriber, a LaserScan and an Image read back out of the graph) and checks it field by
field; a truncated sample is counted, not fatal; a publisher that disappears and returns is picked up again; the
bridge's graph dump holds what was sent. Waits have generous deadlines; nothing is asserted about speed."""

import gc
import math
import os
import shutil
import signal
import tempfile
import time
import unittest

try:
    import ros2_types as ros
    from cyclonedds.core import Qos, Policy
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration
    HAVE_CYCLONE = True
except ImportError:  # the venv of scripts/test-python.sh installs it
    HAVE_CYCLONE = False

import support

# A ROS 2 domain no other test uses.
ROS_DOMAIN = 57
_CDR = Policy.DataRepresentation(use_cdrv0_representation=True)
if HAVE_CYCLONE:
    SENSOR = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5), _CDR)
    DEFAULT = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
                  Policy.History.KeepLast(10), _CDR)
    STATIC = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
                 Policy.History.KeepLast(1), _CDR)


def bridge_file(prefix):
    return f"""
ros_domain = {ROS_DOMAIN}
dsr_prefix = "{prefix}"
agent_id = 201

[[in]]
topic = "/scan_in"
type = "sensor_msgs/msg/LaserScan"
qos = "sensor"

[[in]]
topic = "/image_in"
type = "sensor_msgs/msg/Image"
qos = "default"

[[in]]
topic = "/tf_in"
type = "tf2_msgs/msg/TFMessage"
qos = "default"

[[in]]
topic = "/tf_static_in"
type = "tf2_msgs/msg/TFMessage"
qos = "static"

[tf_out]
rate_hz = 20.0
static_frames = ["laser_frame"]

[[laser_out]]
node = "/scan_in"
topic = "/scan_out"
rate_hz = 100.0
range_min_m = 0.05
range_max_m = 30.0

[[image_out]]
node = "/image_in"
topic = "/image_out"
rate_hz = 100.0
"""


class BridgeProcess(support.StatusProcess):
    """A `cortex bridge ros2` process, its JSON status lines read on a thread."""

    def __init__(self, binary, config_path, dump_path):
        super().__init__([binary, "bridge", "ros2", "--config", config_path, "--join-wait-ms", "300"], dump_path)

    def input(self, topic):
        for counters in self.status().get("bridge", {}).get("inputs", []):
            if counters["topic"] == topic:
                return counters
        return {}

    def output(self, topic):
        for counters in self.status().get("bridge", {}).get("outputs", []):
            if counters["topic"] == topic:
                return counters
        return {}


def yaw_quaternion(yaw):
    return ros.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def transform(stamp, parent, child, translation, yaw):
    x, y, z = translation
    return ros.TransformStamped(
        header=ros.header(stamp, parent), child_frame_id=child,
        transform=ros.Transform(translation=ros.Vector3(x=x, y=y, z=z), rotation=yaw_quaternion(yaw)))


def scan(stamp, ranges):
    n = len(ranges)
    return ros.LaserScan(header=ros.header(stamp, "laser_frame"), angle_min=-0.5, angle_max=0.5,
                         angle_increment=1.0 / (n - 1), time_increment=0.0, scan_time=0.1, range_min=0.05,
                         range_max=30.0, ranges=ranges, intensities=[float(i) for i in range(n)])


def take_until(reader, predicate, timeout_s, what):
    """Takes samples until one satisfies `predicate`; returns it."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for sample in reader.take(N=64):
            if predicate(sample):
                return sample
        time.sleep(0.01)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


def publish_until(writer, sample, condition, timeout_s, what):
    """Writes `sample` every 50 ms until `condition()` (best-effort topics and discovery may drop early ones)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        writer.write(sample)
        if condition():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


def same_rotation(q, yaw):
    want = yaw_quaternion(yaw)
    dot = q.x * want.x + q.y * want.y + q.z * want.z + q.w * want.w
    return abs(abs(dot) - 1.0) < 1e-6


@unittest.skipUnless(HAVE_CYCLONE, "cyclonedds is not installed (scripts/test-python.sh installs it)")
@unittest.skipUnless(support.cortex_binary(), "the cortex binary is not built (cargo build -p harness --bin cortex)")
class Ros2BridgeAgainstCyclone(unittest.TestCase):
    def setUp(self):
        ros.use_loopback()
        self.dir = tempfile.mkdtemp(prefix="cortex_ros2_bridge_")
        config = os.path.join(self.dir, "bridge.toml")
        with open(config, "w") as f:
            f.write(bridge_file(support.topic_prefix("ros2b")))
        self.bridge = BridgeProcess(support.cortex_binary(), config, os.path.join(self.dir, "dump.json"))
        self.dp = DomainParticipant(ROS_DOMAIN)

    def tearDown(self):
        self.bridge.kill()
        shutil.rmtree(self.dir, ignore_errors=True)

    def topic(self, participant, name, kind):
        return Topic(participant, "rt" + name, kind)

    def test_cyclone_and_the_bridge_exchange_ros2_messages_both_ways(self):
        support.wait_until(lambda: self.bridge.status().get("agent", {}).get("ready"), 60, "the bridge's graph")
        dp = self.dp
        # Readers of what the bridge publishes, created before it publishes (the /tf_static one comes later).
        scan_out = DataReader(dp, self.topic(dp, "/scan_out", ros.LaserScan), qos=SENSOR)
        image_out = DataReader(dp, self.topic(dp, "/image_out", ros.Image), qos=DEFAULT)
        tf_topic = self.topic(dp, "/tf", ros.TFMessage)
        tf_out = DataReader(dp, tf_topic, qos=DEFAULT)

        self.check_tf_in(dp)
        self.check_tf_out(tf_out)
        self.check_late_tf_static_subscriber(dp)
        self.check_laser_both_ways(scan_out)
        pixels = self.check_image_both_ways(dp, image_out)
        self.check_truncated_sample_is_counted()
        self.check_publisher_that_returns(scan_out)
        ranges = self.check_resumed_after_a_stop_signal(scan_out)

        symbols = self.bridge.stop()
        by_name = {s["name"]: s for s in symbols.values()}
        laser = by_name["/scan_in"]["attribute"]
        self.assertEqual(by_name["/scan_in"]["type"], "laser")
        dists = laser["laser_dists"]["value"]
        self.assertEqual(len(dists), len(ranges))
        for got, sent in zip(dists, [r * 1000.0 for r in ranges]):
            self.assertAlmostEqual(got, sent, places=2)
        image = by_name["/image_in"]["attribute"]
        self.assertEqual(image["cam_rgb_width"]["value"], 4)
        self.assertEqual(bytes(image["cam_rgb"]["value"]), pixels)

    def check_tf_in(self, dp):
        static_writer = DataWriter(dp, self.topic(dp, "/tf_static_in", ros.TFMessage), qos=STATIC)
        static_writer.write(ros.TFMessage(transforms=[
            transform(time.time_ns(), "base_link", "laser_frame", (0.1, 0.0, 0.3), 0.3),
            transform(time.time_ns(), "base_link", "camera_frame", (0.2, 0.0, 1.2), 0.0)]))
        support.wait_until(lambda: self.bridge.input("/tf_static_in").get("written", 0) >= 1, 60,
                           "the static transforms to be written (transient local: sent before discovery)")
        tf_writer = DataWriter(dp, self.topic(dp, "/tf_in", ros.TFMessage), qos=DEFAULT)
        dynamic = ros.TFMessage(transforms=[transform(time.time_ns(), "world", "base_link", (1.0, -0.5, 0.0),
                                                      math.pi / 2)])
        publish_until(tf_writer, dynamic, lambda: self.bridge.input("/tf_in").get("written", 0) >= 1, 60,
                      "a /tf_in sample to be written")

    def check_tf_out(self, tf_out):
        def has_base(message):
            return any(t.child_frame_id == "base_link" for t in message.transforms)
        message = take_until(tf_out, has_base, 60, "/tf with world -> base_link")
        base = next(t for t in message.transforms if t.child_frame_id == "base_link")
        self.assertEqual(base.header.frame_id, "world")
        v = base.transform.translation
        self.assertAlmostEqual(v.x, 1.0, places=5)
        self.assertAlmostEqual(v.y, -0.5, places=5)
        self.assertAlmostEqual(v.z, 0.0, places=5)
        self.assertTrue(same_rotation(base.transform.rotation, math.pi / 2), base.transform.rotation)
        self.assertLess(abs(ros.stamp_ns(base.header) - time.time_ns()), 60_000_000_000, "stamped now")
        # The static edge is not on /tf.
        self.assertFalse(any(t.child_frame_id == "laser_frame" for t in message.transforms))

    def check_late_tf_static_subscriber(self, dp):
        support.wait_until(lambda: self.bridge.output("/tf_static").get("published", 0) >= 1, 60,
                           "the bridge to publish /tf_static")
        time.sleep(0.5)  # well after the publication: this reader joins late
        late = DataReader(dp, self.topic(dp, "/tf_static", ros.TFMessage), qos=STATIC)
        message = take_until(late, lambda m: len(m.transforms) > 0, 60, "the last /tf_static for a late reader")
        laser = next(t for t in message.transforms if t.child_frame_id == "laser_frame")
        self.assertEqual(laser.header.frame_id, "base_link")
        v = laser.transform.translation
        self.assertAlmostEqual(v.x, 0.1, places=5)
        self.assertAlmostEqual(v.z, 0.3, places=5)
        self.assertTrue(same_rotation(laser.transform.rotation, 0.3), laser.transform.rotation)
        self.assertNotIn("base_link", [t.child_frame_id for t in message.transforms])

    def check_laser_both_ways(self, scan_out):
        self.scan_dp = DomainParticipant(ROS_DOMAIN)
        self.scan_writer = DataWriter(self.scan_dp, self.topic(self.scan_dp, "/scan_in", ros.LaserScan), qos=SENSOR)
        ranges = [1.0, 2.5, 0.5, 4.25, 7.0]
        stamp = time.time_ns()
        sent = scan(stamp, ranges)
        publish_until(self.scan_writer, sent, lambda: self.bridge.input("/scan_in").get("written", 0) >= 1, 60,
                      "a LaserScan to be written")
        got = take_until(scan_out, lambda m: ros.stamp_ns(m.header) == stamp, 60, "the scan back on /scan_out")
        self.assertEqual(got.header.frame_id, "laser_frame")
        self.assertEqual(len(got.ranges), len(ranges))
        for a, b in zip(got.ranges, ranges):
            self.assertAlmostEqual(a, b, places=5)
        self.assertEqual(list(got.intensities), sent.intensities)
        self.assertAlmostEqual(got.angle_min, -0.5, places=6)
        self.assertAlmostEqual(got.angle_max, 0.5, places=6)
        self.assertAlmostEqual(got.angle_increment, 0.25, places=6)
        self.assertAlmostEqual(got.range_min, 0.05, places=6)
        self.assertAlmostEqual(got.range_max, 30.0, places=6)

    def check_image_both_ways(self, dp, image_out):
        writer = DataWriter(dp, self.topic(dp, "/image_in", ros.Image), qos=DEFAULT)
        pixels = bytes((i * 7) % 256 for i in range(4 * 3 * 3))
        stamp = time.time_ns()
        sent = ros.Image(header=ros.header(stamp, "camera_frame"), height=3, width=4, encoding="rgb8",
                         is_bigendian=0, step=12, data=list(pixels))
        publish_until(writer, sent, lambda: self.bridge.input("/image_in").get("written", 0) >= 1, 60,
                      "an Image to be written")
        got = take_until(image_out, lambda m: ros.stamp_ns(m.header) == stamp, 60, "the image back on /image_out")
        self.assertEqual((got.height, got.width, got.step, got.encoding, got.is_bigendian), (3, 4, 12, "rgb8", 0))
        self.assertEqual(got.header.frame_id, "camera_frame")
        self.assertEqual(bytes(got.data), pixels)
        return pixels

    def check_truncated_sample_is_counted(self):
        bad_dp = DomainParticipant(ROS_DOMAIN)
        bad = DataWriter(bad_dp, Topic(bad_dp, "rt/scan_in", ros.TruncatedScan), qos=SENSOR)
        truncated = ros.TruncatedScan(header=ros.header(time.time_ns(), "laser_frame"), angle_min=-0.5)
        publish_until(bad, truncated, lambda: self.bridge.input("/scan_in").get("malformed", 0) >= 1, 60,
                      "a truncated LaserScan to be counted")
        counters = self.bridge.input("/scan_in")
        self.assertIn("LaserScan", counters["last_error"])
        self.assertIsNone(self.bridge.process.poll(), "the bridge is still running")
        del bad, bad_dp
        gc.collect()

    def check_publisher_that_returns(self, scan_out):
        written = self.bridge.input("/scan_in")["written"]
        del self.scan_writer, self.scan_dp
        gc.collect()
        time.sleep(1.0)
        self.scan_dp = DomainParticipant(ROS_DOMAIN)
        self.scan_writer = DataWriter(self.scan_dp, self.topic(self.scan_dp, "/scan_in", ros.LaserScan), qos=SENSOR)
        stamp = time.time_ns()
        ranges = [3.0, 0.125, 3.5]
        publish_until(self.scan_writer, scan(stamp, ranges),
                      lambda: self.bridge.input("/scan_in").get("written", 0) > written, 60,
                      "a scan from the returning publisher to be written")
        got = take_until(scan_out, lambda m: ros.stamp_ns(m.header) == stamp, 60, "the returning publisher's scan")
        self.assertEqual([round(r, 5) for r in got.ranges], ranges)
        return ranges

    def check_resumed_after_a_stop_signal(self, scan_out):
        """rustdds's threads end when a stopped process is resumed: the bridge rebuilds its DDS side and goes on."""
        os.kill(self.bridge.process.pid, signal.SIGSTOP)
        time.sleep(3.0)
        os.kill(self.bridge.process.pid, signal.SIGCONT)
        stamp = time.time_ns()
        ranges = [2.0, 0.25, 6.5, 1.5]

        def came_back():
            # An invalid sample says a writer went away (the bridge's old one, after the rebuild).
            return any(isinstance(m, ros.LaserScan) and ros.stamp_ns(m.header) == stamp for m in scan_out.take(N=64))
        publish_until(self.scan_writer, scan(stamp, ranges), came_back, 60,
                      "a scan through the bridge after SIGSTOP and SIGCONT")
        support.wait_until(lambda: self.bridge.status().get("bridge", {}).get("rebuilds", 0) >= 1, 10,
                           "the bridge's status to count the rebuild")
        return ranges


if __name__ == "__main__":
    unittest.main()
