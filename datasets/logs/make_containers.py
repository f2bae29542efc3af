"""Writes the same real logs in the other containers robot logs come in, and a log of custom messages.

Run from the repository root: python3 datasets/logs/make_containers.py
For the throughput figures of the README: python3 datasets/logs/make_containers.py --bench DIR writes the whole bundled
SICK (10 s) and EuRoC (1 s) logs in every container to DIR (not bundled: about 50 MB).
Needs the Python packages `rosbags` (0.11, which converts between ROS 2 MCAP, ROS 1 bags and rosbag2 directories),
`mcap` (1.x) and `lz4`. Writes datasets/logs/containers/ and the `containers` section of datasets/logs/manifest.json.

What it writes (every file from the bundled ROS 2 MCAP logs in datasets/logs/, cut by log time):

- `husky_10s.mcap` / `sick_1s.mcap`: the first 10 s of the Husky log and the first 1 s of the SICK log, ROS 2 MCAP,
  every message copied byte for byte;
- `*.bag`: the same logs as ROS 1 bags v2.0 (`rosbags-convert`), uncompressed, and rewritten by rosbags' bag
  writer with bz2 and lz4 chunks of about 32 KB (128 KB for SICK), so a file holds several chunks;
- `*_ros1.mcap`: the same ROS 1 bag's messages in MCAP (`ros1` message encoding, `ros1msg` schemas: what
  `mcap convert FILE.bag` writes), bytes copied from the bag;
- `*_sqlite3/` and `*_rosbag2_mcap/`: rosbag2 directories (`metadata.yaml` + `.db3`, or + `.mcap`);
- `custom_radar_diag.*`: ten synthetic messages each of a vendor radar type (`acme_radar_msgs/msg/RadarScan`, defined
  below, with nested arrays, a fixed array and a byte array) and of `diagnostic_msgs/msg/DiagnosticArray`, types the
  bridge has no decoder for, as a rosbag2 MCAP directory (whose `.mcap` is a plain ROS 2 MCAP with `ros2msg` schemas),
  a ROS 1 bag, a ROS 1 MCAP and a rosbag2 sqlite3 directory. The values are made up (deterministic); they exist to
  test decoding from the definitions the files carry.

rosbags writes a ROS 1 bag's connection records with the ROS 1 definitions (`Header header` with `seq`, `time`), and
rosbag2 sqlite3 files at version 9 with the `message_definitions` table.
"""
import hashlib
import json
import os
import shutil
import subprocess
import sys

import numpy as np

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from rosbags.rosbag1 import Reader as Bag1Reader, Writer as Bag1Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Bag2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

LOGS = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(LOGS, "containers")
CONVERT = os.path.join(os.path.dirname(sys.executable), "rosbags-convert")


def excerpt(src, dst, seconds, compression):
    """Copies the messages of the first `seconds` of log time of `src` into a new ROS 2 MCAP `dst`."""
    with open(os.path.join(LOGS, src), "rb") as f_in, open(os.path.join(OUT, dst), "wb") as f_out:
        reader = make_reader(f_in)
        writer = Writer(f_out, chunk_size=256 * 1024, compression=compression)
        writer.start(profile=reader.get_header().profile, library="cortex-rs datasets/logs/make_containers.py")
        schema_ids, channel_ids, start = {}, {}, None
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            start = message.log_time if start is None else start
            if message.log_time - start >= seconds * 1_000_000_000:
                break
            if schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channel_ids:
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_ids[schema.id], dict(channel.metadata))
            writer.add_message(channel_ids[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer.finish()


def convert(src, dst, *extra):
    """Runs rosbags-convert from `src` to `dst` (both in OUT)."""
    target = os.path.join(OUT, dst)
    if os.path.isdir(target):
        shutil.rmtree(target)
    elif os.path.exists(target):
        os.remove(target)
    subprocess.run([CONVERT, "--src", os.path.join(OUT, src), "--dst", target, *extra], check=True)


def rechunk(src, dst, compression, chunk_bytes=32 * 1024):
    """Rewrites a ROS 1 bag with `compression` (`bz2` or `lz4`) chunks of about `chunk_bytes` (several per file)."""
    target = os.path.join(OUT, dst)
    if os.path.exists(target):
        os.remove(target)
    with Bag1Reader(os.path.join(OUT, src)) as bag:
        writer = Bag1Writer(target)
        writer.set_compression(getattr(Bag1Writer.CompressionFormat, compression.upper()))
        writer.chunk_threshold = chunk_bytes
        with writer:
            connections = {}
            for c in bag.connections:
                connections[c.id] = writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                                                          callerid=c.ext.callerid, latching=c.ext.latching)
            for connection, timestamp, raw in bag.messages():
                writer.write(connections[connection.id], timestamp, bytes(raw))


def bag_to_ros1_mcap(src, dst):
    """Copies a ROS 1 bag's messages into MCAP with `ros1` encoding and `ros1msg` schemas (the bag's definitions)."""
    with Bag1Reader(os.path.join(OUT, src)) as bag, open(os.path.join(OUT, dst), "wb") as f_out:
        writer = Writer(f_out, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        writer.start(profile="ros1", library="cortex-rs datasets/logs/make_containers.py")
        channels = {}
        for connection in bag.connections:
            ros1_name = connection.msgtype.replace("/msg/", "/")
            schema = writer.register_schema(ros1_name, "ros1msg", connection.msgdef.data.encode())
            metadata = {"md5sum": connection.digest}
            channels[connection.id] = writer.register_channel(connection.topic, "ros1", schema, metadata)
        for sequence, (connection, timestamp, raw) in enumerate(bag.messages()):
            writer.add_message(channels[connection.id], timestamp, bytes(raw), timestamp, sequence)
        writer.finish()


RADAR_TARGET = """
float32 range
float32 azimuth
float32 radial_velocity
int16 rcs
string label
"""

RADAR_SCAN = """
# A vendor radar scan: targets, a noise floor per range gate and the raw frame.
uint8 MODE_SHORT=0
uint8 MODE_LONG=1
std_msgs/Header header
uint32 scan_id
uint8 mode
bool valid
float64[3] sensor_position
acme_radar_msgs/RadarTarget[] targets
float32[] noise_floor
uint8[] raw_frame
string firmware
"""


def custom_log(dst_dir):
    """Ten radar scans and ten diagnostic arrays at 10 Hz, as a rosbag2 MCAP directory."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    types.update(get_types_from_msg(RADAR_TARGET, "acme_radar_msgs/msg/RadarTarget"))
    types.update(get_types_from_msg(RADAR_SCAN, "acme_radar_msgs/msg/RadarScan"))
    store.register(types)
    t = store.types
    target = os.path.join(OUT, dst_dir)
    if os.path.isdir(target):
        shutil.rmtree(target)
    start_ns = 1_700_000_000_000_000_000
    with Bag2Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        radar = writer.add_connection("/radar/scan", "acme_radar_msgs/msg/RadarScan", typestore=store)
        diag = writer.add_connection("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", typestore=store)
        for i in range(10):
            now = start_ns + i * 100_000_000
            stamp = t["builtin_interfaces/msg/Time"](sec=now // 1_000_000_000, nanosec=now % 1_000_000_000)
            header = t["std_msgs/msg/Header"](stamp=stamp, frame_id="radar_link")
            targets = [t["acme_radar_msgs/msg/RadarTarget"](range=10.0 + i + k, azimuth=0.1 * k,
                                                            radial_velocity=-1.5 + 0.25 * k, rcs=-5 + k,
                                                            label=f"target-{k}") for k in range(3)]
            scan = t["acme_radar_msgs/msg/RadarScan"](
                header=header, scan_id=1000 + i, mode=1, valid=(i % 2 == 0),
                sensor_position=np.array([0.5, 0.0, 1.25]),
                targets=targets,
                noise_floor=np.array([-90.0 + i, -91.0, -92.5, -93.0], dtype="float32"),
                raw_frame=np.array([(i * 7 + k) % 256 for k in range(16)], dtype="uint8"),
                firmware="2.4.1")
            writer.write(radar, now, store.serialize_cdr(scan, "acme_radar_msgs/msg/RadarScan"))
            kv = t["diagnostic_msgs/msg/KeyValue"]
            status = [t["diagnostic_msgs/msg/DiagnosticStatus"](
                level=k % 3, name=f"radar/{part}", message="ok" if k else "warm",
                hardware_id="acme-r1", values=[kv(key="temperature_c", value=f"{40 + i}.{k}"),
                                               kv(key="frames", value=str(i * 10))])
                for k, part in enumerate(["front", "rear"])]
            array = t["diagnostic_msgs/msg/DiagnosticArray"](header=header, status=status)
            writer.write(diag, now + 1000, store.serialize_cdr(array, "diagnostic_msgs/msg/DiagnosticArray"))


def sha256(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def manifest_entries():
    """One entry per container: its files with sizes and sha256, the container, the encoding and the source."""
    entries = []
    for name in sorted(os.listdir(OUT)):
        path = os.path.join(OUT, name)
        files = sorted(os.listdir(path)) if os.path.isdir(path) else [None]
        members = [(os.path.join(name, f) if f else name) for f in files]
        if os.path.isdir(path):
            text = open(os.path.join(path, "metadata.yaml")).read()
            container = "rosbag2 " + ("sqlite3" if "storage_identifier: sqlite3" in text else "mcap")
            encoding = "cdr"
        elif name.endswith(".bag"):
            container, encoding = "ros1 bag v2.0", "ros1"
        else:
            container = "mcap"
            encoding = "ros1" if name.endswith("_ros1.mcap") else "cdr"
        source = ("synthetic custom messages (acme_radar_msgs/msg/RadarScan, diagnostic_msgs/msg/DiagnosticArray)"
                  if name.startswith("custom") else
                  "husky_gps_imu_odom_robot_localization_test1.mcap, first 10 s" if name.startswith("husky") else
                  "sick_tim7xx_scan_10s.mcap, first 1 s")
        licence = ("CC0-1.0 (made up for the tests)" if name.startswith("custom") else
                   "Apache-2.0 (robot_localization)" if name.startswith("husky") else "Apache-2.0 (SICK AG)")
        for member in members:
            p = os.path.join(OUT, member)
            entries.append({"file": "containers/" + member, "bytes": os.path.getsize(p), "sha256": sha256(p),
                            "container": container, "encoding": encoding, "source": source, "licence": licence})
    return entries


def bench(out):
    """The bundled SICK and EuRoC logs whole, in every container, in `out` (for throughput measurements)."""
    global OUT
    OUT = out
    os.makedirs(OUT, exist_ok=True)
    for name, log in [("sick", "sick_tim7xx_scan_10s.mcap"), ("euroc", "euroc_v1_01_easy_cam0_1s.mcap")]:
        shutil.copyfile(os.path.join(LOGS, log), os.path.join(OUT, f"{name}.mcap"))
        convert(f"{name}.mcap", f"{name}.bag")
        rechunk(f"{name}.bag", f"{name}_bz2.bag", "bz2", 768 * 1024)
        rechunk(f"{name}.bag", f"{name}_lz4.bag", "lz4", 768 * 1024)
        bag_to_ros1_mcap(f"{name}_lz4.bag", f"{name}_ros1.mcap")
        convert(f"{name}.mcap", f"{name}_sqlite3", "--dst-storage", "sqlite3")
        convert(f"{name}.mcap", f"{name}_rosbag2_mcap", "--dst-storage", "mcap")


def main():
    if sys.argv[1:2] == ["--bench"]:
        bench(os.path.abspath(sys.argv[2]))
        return
    os.makedirs(OUT, exist_ok=True)
    excerpt("husky_gps_imu_odom_robot_localization_test1.mcap", "husky_10s.mcap", 10, CompressionType.ZSTD)
    excerpt("sick_tim7xx_scan_10s.mcap", "sick_1s.mcap", 1, CompressionType.LZ4)
    custom_log("custom_radar_diag_rosbag2_mcap")
    convert("husky_10s.mcap", "husky_10s.bag")
    rechunk("husky_10s.bag", "husky_10s_bz2.bag", "bz2")
    rechunk("husky_10s.bag", "husky_10s_lz4.bag", "lz4")
    convert("husky_10s.mcap", "husky_10s_sqlite3", "--dst-storage", "sqlite3")
    convert("husky_10s.mcap", "husky_10s_rosbag2_mcap", "--dst-storage", "mcap")
    bag_to_ros1_mcap("husky_10s_bz2.bag", "husky_10s_ros1.mcap")
    convert("sick_1s.mcap", "sick_1s.bag")
    rechunk("sick_1s.bag", "sick_1s_lz4.bag", "lz4", 128 * 1024)
    os.remove(os.path.join(OUT, "sick_1s.bag"))
    convert("sick_1s.mcap", "sick_1s_sqlite3", "--dst-storage", "sqlite3")
    bag_to_ros1_mcap("sick_1s_lz4.bag", "sick_1s_ros1.mcap")
    convert("custom_radar_diag_rosbag2_mcap", "custom_radar_diag.bag")
    convert("custom_radar_diag_rosbag2_mcap", "custom_radar_diag_sqlite3", "--dst-storage", "sqlite3")
    bag_to_ros1_mcap("custom_radar_diag.bag", "custom_radar_diag_ros1.mcap")
    manifest_path = os.path.join(LOGS, "manifest.json")
    manifest = json.load(open(manifest_path))
    manifest["containers"] = manifest_entries()
    with open(manifest_path, "w") as f:
        json.dump(manifest, f, indent=2)
        f.write("\n")


if __name__ == "__main__":
    main()
