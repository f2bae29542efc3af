"""The cost of cortex_dsr's hot paths from Python, beside the C++ pydsr figures in shared/FACTS.md (local
update_node ~0.1-0.15 ms up to 150 KB of attributes, ~0.8 ms at 1 MB).

Measured:
- `g.update_node(node)` with one changed attribute of N bytes (a uint8 vector; N = 4 is a float), the node's
  attribute set beforehand (`attrs[...].value = array`, itself measured on its own line);
- reading a 640x480 image attribute into numpy: `node.attrs["cam_rgb"].value` (one memcpy out of the attribute's
  buffer), and the whole `g.get_node("camera").attrs["cam_rgb"].value`, for mono8 (307,200 B) and rgb8 (921,600 B).

The agent runs alone on a topic of its own (no peer: like pydsr's local figure, the publish goes to no reader).
Run: python python/bench/bench_python_api.py [--quick]   (after `pip install ./python`, a release build)
Prints one Markdown table with medians and p99 in microseconds, and the machine it ran on.
"""

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import cortex_dsr
from cortex_dsr import Attribute, DSRGraph, Node


def percentile(samples, q):
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(round(q * (len(ordered) - 1))))]


def measure(label, iterations, prepare, action):
    """Times `action(i)` alone (after an untimed `prepare(i)`), `iterations` times after 10 warm-up rounds."""
    for i in range(10):
        prepare(i)
        action(i)
    samples = []
    for i in range(iterations):
        prepare(i)
        start = time.perf_counter_ns()
        action(i)
        samples.append((time.perf_counter_ns() - start) / 1000.0)
    return {"what": label, "n": iterations, "median_us": statistics.median(samples),
            "p99_us": percentile(samples, 0.99)}


def machine():
    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
    except OSError:
        commit = "?"
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "os": platform.platform(), "commit": commit}


def seed_file(directory):
    symbols = {
        "1": {"id": 1, "type": "root", "name": "root", "attribute": {}, "links": []},
        "2": {"id": 2, "type": "rgbd", "name": "camera", "attribute": {}, "links": []},
    }
    path = os.path.join(directory, "bench.json")
    with open(path, "w") as f:
        json.dump({"DSRModel": {"symbols": symbols}}, f)
    return path


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer iterations (a smoke run)")
    args = parser.parse_args()
    scale = 10 if args.quick else 1

    directory = tempfile.mkdtemp(prefix="cortex_dsr_bench_")
    g = DSRGraph(0, "bench", 30, seed_file(directory), topic_prefix=f"bench{os.getpid()}", join_wait_ms=300)
    rows = []

    # update_node with one changed attribute of each size (two buffers alternate, so every call writes).
    for size in (4, 1024, 10 * 1024, 150 * 1024, 1024 * 1024):
        node = g.get_node("root")
        if size == 4:
            values = [1.0, 2.0]
            node.attrs["pos_x"] = Attribute(0.0, 30)
            set_value = lambda i: setattr(node.attrs["pos_x"], "value", values[i % 2])  # noqa: E731
        else:
            buffers = [np.full(size, k, dtype=np.uint8) for k in (1, 2)]
            node.attrs["cam_depth"] = Attribute(buffers[0], 30)
            set_value = lambda i: setattr(node.attrs["cam_depth"], "value", buffers[(i + 1) % 2])  # noqa: E731
        iterations = max(20, (2000 if size <= 150 * 1024 else 500) // scale)
        label = "float attribute" if size == 4 else f"{size:,} B attribute"
        rows.append(measure(f"update_node, {label}", iterations, set_value, lambda i: g.update_node(node)))
        if size == 1024 * 1024:
            rows.append(measure("attrs[...].value = 1 MiB numpy array (copy in)", iterations, lambda i: None,
                                set_value))
        # Leave the node without the big attribute for the next size.
        node = g.get_node("root")
        if "cam_depth" in node.attrs:
            del node.attrs["cam_depth"]
            g.update_node(node)

    # Reading an image attribute into numpy.
    for label, shape in (("mono8 640x480 (307,200 B)", (480, 640)), ("rgb8 640x480 (921,600 B)", (480, 640, 3))):
        camera = g.get_node("camera")
        camera.attrs["cam_rgb"] = Attribute(np.random.default_rng(1).integers(0, 255, shape, dtype=np.uint8), 30)
        g.update_node(camera)
        camera = g.get_node("camera")
        attribute = camera.attrs["cam_rgb"]
        iterations = max(20, 1000 // scale)
        rows.append(measure(f"attr.value -> numpy, {label}", iterations, lambda i: None, lambda i: attribute.value))
        rows.append(measure(f"get_node + attr.value -> numpy, {label}", iterations, lambda i: None,
                            lambda i: g.get_node("camera").attrs["cam_rgb"].value))

    g.close()
    info = machine()
    print(f"cortex_dsr {getattr(cortex_dsr, '__version__', '')} benchmark: {' '.join(sys.argv)}")
    print(f"machine: {info['cpu']}, {info['cores']} cores; {info['os']}; Python {info['python']}, "
          f"numpy {info['numpy']}; commit {info['commit']}")
    print()
    print("| what | n | median (us) | p99 (us) |")
    print("|---|---|---|---|")
    for row in rows:
        print(f"| {row['what']} | {row['n']} | {row['median_us']:.1f} | {row['p99_us']:.1f} |")


if __name__ == "__main__":
    main()
