"""Cuts the bundled replay logs from ../shared/datasets and writes manifest.json.

Run from the repository root: python3 datasets/logs/make_subsets.py [SHARED_DATASETS_DIR]
Needs the `mcap` Python package (1.x, with zstandard and lz4). Every message is copied byte for byte (same
channel, schema, log time, publish time and sequence); only the selection, the chunking and the chunk
compression differ from the source file. The husky log is copied whole.
"""
import hashlib
import json
import os
import shutil
import sys
from collections import Counter

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

SRC = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "../../../shared/datasets")
OUT = os.path.dirname(os.path.abspath(__file__))


def cut(src, dst, keep, compression, chunk_size=512 * 1024):
    """Copies the messages for which keep(topic, log_time_from_start_ns, index_in_topic) is true."""
    with open(os.path.join(SRC, src), "rb") as f_in, open(os.path.join(OUT, dst), "wb") as f_out:
        reader = make_reader(f_in)
        writer = Writer(f_out, chunk_size=chunk_size, compression=compression)
        writer.start(profile=reader.get_header().profile, library="cortex-rs datasets/logs/make_subsets.py")
        schema_ids, channel_ids, seen = {}, {}, Counter()
        start = None
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            start = message.log_time if start is None else start
            index = seen[channel.topic]
            seen[channel.topic] += 1
            if not keep(channel.topic, message.log_time - start, index):
                continue
            if schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channel_ids:
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_ids[schema.id], dict(channel.metadata)
                )
            writer.add_message(channel_ids[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer.finish()


cut("euroc_v1_01_easy_excerpt.mcap", "euroc_v1_01_easy_cam0_1s.mcap",
    lambda topic, t, i: not topic.startswith("/cam1/") and t < 1_000_000_000, CompressionType.ZSTD)
cut("ouster_os1-128_3scans.mcap", "ouster_os1-128_1scan.mcap",
    lambda topic, t, i: topic in ("/ouster/metadata", "/ouster/imu_packets") and i < 10
    or topic == "/ouster/points" and i == 0 or topic == "/ouster/lidar_packets" and i < 8,
    CompressionType.ZSTD)
cut("sick_tim7xx_scan_20210106_51s.mcap", "sick_tim7xx_scan_10s.mcap",
    lambda topic, t, i: t < 10_000_000_000, CompressionType.LZ4)
shutil.copyfile(os.path.join(SRC, "husky_gps_imu_odom_robot_localization_test1.mcap"),
                os.path.join(OUT, "husky_gps_imu_odom_robot_localization_test1.mcap"))

SOURCES = {
    "euroc_v1_01_easy_cam0_1s.mcap": {
        "cut_of": "euroc_v1_01_easy_excerpt.mcap (shared datasets): first 1.0 s of log time, /cam1/* dropped",
        "source": "EuRoC MAV dataset V1_01_easy (ASL, ETH Zurich) via MIT-SPARK/Kimera-VIO tests/data/MicroEurocDataset; "
                  "ground truth via MichaelGrupp/evo test/data/V101_gt.txt",
        "licence": "Kimera-VIO BSD-2-Clause (images, IMU); EuRoC data by ASL/ETH Zurich, cite M. Burri et al., "
                   "'The EuRoC micro aerial vehicle datasets', IJRR 2016; evo ground-truth file GPL-3.0",
    },
    "ouster_os1-128_1scan.mcap": {
        "cut_of": "ouster_os1-128_3scans.mcap (shared datasets): first /ouster/points scan, metadata, "
                  "first 8 lidar packets and first 10 IMU packets",
        "source": "ouster-lidar/ouster-sdk tests/pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap",
        "licence": "BSD-3-Clause (Ouster)",
    },
    "sick_tim7xx_scan_10s.mcap": {
        "cut_of": "sick_tim7xx_scan_20210106_51s.mcap (shared datasets): first 10 s of log time, lz4 chunks",
        "source": "SICKAG/sick_scan_xd test/pcap_json_converter/example.pcapng (CoLa-B stream, decoded)",
        "licence": "Apache-2.0 (SICK AG)",
    },
    "husky_gps_imu_odom_robot_localization_test1.mcap": {
        "cut_of": "husky_gps_imu_odom_robot_localization_test1.mcap (shared datasets), whole file, unchanged",
        "source": "cra-ros-pkg/robot_localization test/test1.bag (ROS 1), converted to ROS 2 MCAP",
        "licence": "Apache-2.0 (robot_localization)",
    },
}

files = []
for name, info in SOURCES.items():
    path = os.path.join(OUT, name)
    data = open(path, "rb").read()
    with open(path, "rb") as f:
        reader = make_reader(f)
        topics = {}
        first = last = None
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            entry = topics.setdefault(channel.topic, {"topic": channel.topic, "type": schema.name, "count": 0})
            entry["count"] += 1
            first = message.log_time if first is None else first
            last = message.log_time
    files.append({
        "file": name, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest(),
        "container": "mcap", "encoding": "cdr", "log_start_ns": first, "log_end_ns": last, **info,
        "topics": sorted(topics.values(), key=lambda t: t["topic"]),
    })
# The same logs in other containers (make_containers.py) keep their list.
manifest_path = os.path.join(OUT, "manifest.json")
containers = json.load(open(manifest_path)).get("containers", []) if os.path.exists(manifest_path) else []
with open(manifest_path, "w") as f:
    json.dump({"version": 1, "files": files, "containers": containers}, f, indent=2)
    f.write("\n")
print(json.dumps([(f["file"], f["bytes"]) for f in files]))
