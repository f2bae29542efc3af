#!/usr/bin/env python3
"""Latency of `cortex bridge ros2` against Eclipse Cyclone DDS on loopback (a benchmark, not a test).

A Cyclone participant publishes LaserScans on /bench_in (header stamp = the wall clock just before the write); the
bridge writes each into the graph and publishes the node back out on /bench_out, where a Cyclone reader takes it.
Reported, each as median and p99 over the same samples:

  raw delivery      stamp -> sample taken from the bridge's rustdds reader (Cyclone -> rustdds, in the bridge)
  pub -> graph      stamp -> the sample's deltas written into the graph and published (in the bridge)
  graph -> DDS      graph change signal -> the LaserScan written to DDS (in the bridge)
  pub -> graph -> sub  stamp -> the scan back at the Cyclone reader (here; all on one host clock)

With `--from-graph`, the other direction on its own, per sample: this script is also a graph agent (`cortex_dsr`)
and writes a laser node's `laser_dists`, `laser_angles` and `stamp_ns` (the wall clock just before the write) in one
`update_node`; the bridge, another agent of the same graph, publishes the node as a LaserScan whose header stamp is
`stamp_ns`, and a Cyclone reader here takes it:

  graph write -> sub   stamp -> the scan at the Cyclone reader (a write in one agent, replicated over RTPS to
                       the bridge agent, published to Cyclone; all on one host clock)

Usage (the venv of scripts/test-python.sh has cyclonedds and, for --from-graph, cortex_dsr; build that with
`maturin develop --release` for a figure that does not include a debug build's cost):

  target/python-venv/bin/python scripts/bench-ros2-bridge.py [--count 1000] [--rate-hz 100] [--beams 360]
      [--cortex target/release/cortex] [--qos sensor|default] [--from-graph]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python", "tests"))
import ros2_types as ros  # noqa: E402

ros.use_loopback()
from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

ROS_DOMAIN = 58


def qos(kind):
    cdr = Policy.DataRepresentation(use_cdrv0_representation=True)
    if kind == "sensor":
        return Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5), cdr)
    return Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
               Policy.History.KeepLast(10), cdr)


def percentile(values, p):
    ordered = sorted(values)
    if not ordered:
        return 0
    index = min(len(ordered), max(1, int(-(-p * len(ordered) // 1)))) - 1
    return ordered[index]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--rate-hz", type=float, default=100.0)
    parser.add_argument("--beams", type=int, default=360)
    parser.add_argument("--qos", choices=["sensor", "default"], default="sensor")
    parser.add_argument("--cortex", default=os.path.join("target", "release", "cortex"))
    parser.add_argument("--from-graph", action="store_true", help="graph write -> Cyclone subscriber, per sample")
    args = parser.parse_args()
    if args.from_graph:
        return from_graph(args)

    bridge, latest = start_bridge(args, f"""ros_domain = {ROS_DOMAIN}
dsr_prefix = "ros2bench{os.getpid()}"
agent_id = 210
[[in]]
topic = "/bench_in"
type = "sensor_msgs/msg/LaserScan"
qos = "{args.qos}"
[[laser_out]]
node = "/bench_in"
topic = "/bench_out"
rate_hz = 10000.0
qos = "{args.qos}"
""")
    dp = DomainParticipant(ROS_DOMAIN)
    writer = DataWriter(dp, Topic(dp, "rt/bench_in", ros.LaserScan), qos=qos(args.qos))
    received = take_scans(dp, args.qos)

    deadline = time.monotonic() + 60
    ranges = [1.0 + (i % 100) / 100 for i in range(args.beams)]
    # Warm-up until the round trip works (discovery both ways), not counted.
    while not received and time.monotonic() < deadline:
        writer.write(ros.LaserScan(header=ros.header(time.time_ns(), "laser"), angle_min=-1.0, angle_max=1.0,
                                   angle_increment=2.0 / (args.beams - 1), time_increment=0.0, scan_time=0.0,
                                   range_min=0.0, range_max=30.0, ranges=ranges, intensities=[]))
        time.sleep(0.1)
    if not received:
        sys.exit("no scan came back within 60 s")
    time.sleep(0.5)
    received.clear()
    before = latest["bridge"]["latency_in"][0]["taken"]["count"]
    sent = []
    period = 1.0 / args.rate_hz
    next_at = time.monotonic()
    for _ in range(args.count):
        stamp = time.time_ns()
        writer.write(ros.LaserScan(header=ros.header(stamp, "laser"), angle_min=-1.0, angle_max=1.0,
                                   angle_increment=2.0 / (args.beams - 1), time_increment=0.0, scan_time=0.0,
                                   range_min=0.0, range_max=30.0, ranges=ranges, intensities=[]))
        sent.append(stamp)
        next_at += period
        time.sleep(max(0.0, next_at - time.monotonic()))
    time.sleep(1.0)
    bridge.stdin.close()
    bridge.wait(timeout=30)
    status = latest["bridge"]
    e2e_us = [(received[s] - s) / 1000 for s in sent if s in received]
    lat_in = status["latency_in"][0]
    load = open("/proc/loadavg").read().split()[:3]
    print(f"ROS 2 bridge latency, {args.count} LaserScans of {args.beams} beams at {args.rate_hz:g} Hz, QoS "
          f"{args.qos}, loopback, load average {' '.join(load)}, {os.cpu_count()} cores")
    print("note: the bridge keeps its last 8192 samples; the warm-up samples are in its figures "
          f"({lat_in['taken']['count'] - before} of {lat_in['taken']['count']} are from this run)")
    rows = [
        ("raw delivery (Cyclone -> rustdds reader)", lat_in["taken"]["p50_us"], lat_in["taken"]["p99_us"]),
        ("pub -> graph", lat_in["in_graph"]["p50_us"], lat_in["in_graph"]["p99_us"]),
        ("graph change -> DDS write (bridge)", status["latency_out"]["p50_us"], status["latency_out"]["p99_us"]),
        ("pub -> graph -> Cyclone subscriber", percentile(e2e_us, 0.5), percentile(e2e_us, 0.99)),
    ]
    for name, p50, p99 in rows:
        print(f"  {name:42s} p50 {p50:9.0f} us   p99 {p99:9.0f} us")
    print(f"  {'graph -> subscriber (estimate: difference of medians)':42s} p50 "
          f"{percentile(e2e_us, 0.5) - lat_in['in_graph']['p50_us']:9.0f} us")
    print(f"  samples back: {len(e2e_us)} of {len(sent)}; bridge counters: {json.dumps(status['inputs'][0])}")


def take_scans(dp, qos_kind):
    """Takes the LaserScans on /bench_out on a thread; returns {header stamp: wall clock when taken}."""
    reader = DataReader(dp, Topic(dp, "rt/bench_out", ros.LaserScan), qos=qos(qos_kind))
    received = {}

    def take():
        while True:
            for sample in reader.take(N=64):
                if isinstance(sample, ros.LaserScan):  # else an invalid sample: the writer went away
                    received.setdefault(ros.stamp_ns(sample.header), time.time_ns())
            time.sleep(0.0002)
    threading.Thread(target=take, daemon=True).start()
    return received


def start_bridge(args, config_text):
    """Starts `cortex bridge ros2` on a file of `config_text`; returns the process and its latest status."""
    workdir = tempfile.mkdtemp(prefix="cortex_ros2_bench_")
    config = os.path.join(workdir, "bridge.toml")
    with open(config, "w") as f:
        f.write(config_text)
    bridge = subprocess.Popen([args.cortex, "bridge", "ros2", "--config", config, "--json-status", "--status-ms",
                               "200", "--state-dir", "none", "--control-stdin", "--join-wait-ms", "300"],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    latest = {}

    def read_status():
        for line in bridge.stdout:
            try:
                latest.update(json.loads(line))
            except ValueError:
                pass
    threading.Thread(target=read_status, daemon=True).start()
    deadline = time.monotonic() + 60
    while not latest.get("agent", {}).get("ready") and time.monotonic() < deadline:
        time.sleep(0.05)
    if not latest.get("agent", {}).get("ready"):
        sys.exit("the bridge's agent did not become ready within 60 s")
    return bridge, latest


def from_graph(args):
    """Graph write (this script's agent) -> bridge agent -> Cyclone subscriber, per sample."""
    from cortex_dsr import Attribute, DSRGraph, Node
    import numpy as np

    prefix = f"ros2benchg{os.getpid()}"
    bridge, latest = start_bridge(args, f"""ros_domain = {ROS_DOMAIN}
dsr_prefix = "{prefix}"
agent_id = 210
[[laser_out]]
node = "bench_laser"
topic = "/bench_out"
rate_hz = 10000.0
qos = "{args.qos}"
""")
    graph = DSRGraph(0, "bench", 211, topic_prefix=prefix, join_wait_ms=3000)
    received = take_scans(DomainParticipant(ROS_DOMAIN), args.qos)

    dists = np.array([1000.0 + (i % 100) * 10 for i in range(args.beams)], dtype=np.float32)
    angles = np.linspace(-1.0, 1.0, args.beams, dtype=np.float32)
    node = Node(211, "laser", "bench_laser")
    node.attrs["laser_dists"] = Attribute(dists, 211)
    node.attrs["laser_angles"] = Attribute(angles, 211)
    node.attrs["stamp_ns"] = Attribute(time.time_ns(), 211)
    graph.insert_node(node)

    def write(stamp):
        # update_node sends only what changed, and the bridge publishes on a new `laser_dists` write: vary a beam.
        dists[0] = float(stamp % 1_000_000) / 100.0
        node = graph.get_node("bench_laser")
        node.attrs["laser_dists"] = Attribute(dists, 211)
        node.attrs["stamp_ns"] = Attribute(stamp, 211)
        graph.update_node(node)

    deadline = time.monotonic() + 60
    while not received and time.monotonic() < deadline:  # warm-up: discovery both ways, not counted
        write(time.time_ns())
        time.sleep(0.1)
    if not received:
        sys.exit("no scan reached the Cyclone reader within 60 s")
    time.sleep(0.5)
    received.clear()
    sent = []
    period = 1.0 / args.rate_hz
    next_at = time.monotonic()
    for _ in range(args.count):
        stamp = time.time_ns()
        write(stamp)
        sent.append(stamp)
        next_at += period
        time.sleep(max(0.0, next_at - time.monotonic()))
    time.sleep(1.0)
    graph.close()
    bridge.stdin.close()
    bridge.wait(timeout=30)
    us = [(received[s] - s) / 1000 for s in sent if s in received]
    load = open("/proc/loadavg").read().split()[:3]
    print(f"ROS 2 bridge, graph -> subscriber: {args.count} laser writes of {args.beams} beams at {args.rate_hz:g} Hz "
          f"in a second agent, QoS {args.qos}, loopback, load average {' '.join(load)}, {os.cpu_count()} cores")
    print(f"  {'graph write -> Cyclone subscriber':42s} p50 {percentile(us, 0.5):9.0f} us   "
          f"p99 {percentile(us, 0.99):9.0f} us")
    print(f"  samples: {len(us)} of {len(sent)}; bridge status: {json.dumps(latest['bridge'].get('outputs'))}")


if __name__ == "__main__":
    main()
