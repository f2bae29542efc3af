"""Shared helpers of the cortex_dsr tests: a small CORTEX JSON graph, graphs on topics of their own, waits on
conditions with a deadline (never on speed), and the `cortex` binary for the two-process test."""

import itertools
import json
import os
import shutil
import subprocess
import tempfile
import threading
import time
import unittest

# Each graph of a test gets its own topic prefix on domain 0, so no agent of another test (or of another run of
# the suite) answers its graph request: it starts alone from the fixture after a short join wait.
_PREFIXES = itertools.count(1)


def topic_prefix(tag="py"):
    return f"{tag}{os.getpid()}_{next(_PREFIXES)}"


def rt_link(src, dst, translation, rotation):
    return {
        "src": src,
        "dst": dst,
        "label": "RT",
        "linkAttribute": {
            "rt_translation": {"type": 3, "value": list(translation)},
            "rt_rotation_euler_xyz": {"type": 3, "value": list(rotation)},
        },
    }


def symbol(node_id, node_type, name, attributes=None, links=()):
    return {
        "id": node_id,
        "type": node_type,
        "name": name,
        "attribute": attributes or {},
        "links": list(links),
    }


def fixture_graph():
    """root(1) -RT-> robot(2) -RT-> laser(3); robot -RT-> camera(4, the only rgbd); root -RT-> table(5);
    mesh(203) loose (no parent), as a target for RT edges made by the tests."""
    level = lambda n: {"type": 1, "value": n}  # noqa: E731
    parent = lambda n: {"type": 7, "value": n}  # noqa: E731
    symbols = [
        symbol(1, "root", "root", {"color": {"type": 0, "value": "blue"}, "level": level(0)},
               [rt_link(1, 2, [1000.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
                rt_link(1, 5, [0.0, 2000.0, 0.0], [0.0, 0.0, 1.5707964])]),
        symbol(2, "omnirobot", "robot", {"level": level(1), "parent": parent(1)},
               [rt_link(2, 3, [0.0, 0.0, 300.0], [0.0, 0.0, 0.0]),
                rt_link(2, 4, [100.0, 0.0, 1200.0], [0.0, 0.0, 0.0])]),
        symbol(3, "laser", "laser", {"level": level(2), "parent": parent(2)}),
        symbol(4, "rgbd", "camera", {"level": level(2), "parent": parent(2),
                                     "cam_rgb_width": {"type": 1, "value": 4}}),
        symbol(5, "plane", "table", {"level": level(1), "parent": parent(1)}),
        symbol(203, "mesh", "mesh_203", {}),
    ]
    return {"DSRModel": {"symbols": {str(s["id"]): s for s in symbols}}}


class Fixture:
    """The fixture graph written to a temporary file."""

    def __init__(self):
        self.dir = tempfile.mkdtemp(prefix="cortex_dsr_test_")
        self.path = os.path.join(self.dir, "fixture.json")
        with open(self.path, "w") as f:
            json.dump(fixture_graph(), f)

    def remove(self):
        shutil.rmtree(self.dir, ignore_errors=True)


def new_graph(path, agent_id=12, prefix=None, join_wait_ms=300):
    """A DSRGraph that starts alone from `path` (pydsr's arguments, plus this test's own topic)."""
    import cortex_dsr  # here, so that tests of the `cortex` binary alone (the ROS 2 bridge's) run without the module

    return cortex_dsr.DSRGraph(0, "test", agent_id, path, True,
                               topic_prefix=prefix or topic_prefix(), join_wait_ms=join_wait_ms)


def wait_until(condition, timeout_s=20.0, what="the condition"):
    """Polls `condition` until it is true; fails the test after `timeout_s` (a bound, never a speed claim)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.01)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


def cortex_binary():
    """The `cortex` binary: $CORTEX_BIN, else the cargo target directory's debug or release build."""
    explicit = os.environ.get("CORTEX_BIN")
    if explicit:
        return explicit
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(root, "target"))
    for profile in ("debug", "release"):
        candidate = os.path.join(target, profile, "cortex")
        if os.access(candidate, os.X_OK):
            return candidate
    return None


class GraphTestCase(unittest.TestCase):
    """A test with a fresh graph (`self.g`) started alone from the fixture on a topic of its own, closed after."""

    @classmethod
    def setUpClass(cls):
        cls.fixture = Fixture()

    @classmethod
    def tearDownClass(cls):
        cls.fixture.remove()

    def setUp(self):
        self.g = new_graph(self.fixture.path)

    def tearDown(self):
        self.g.close()


class StatusProcess:
    """A `cortex` process started with `--json-status --control-stdin --dump-json DUMP`: its latest status line,
    read on a thread; `stop` ends it as end of input does and returns the dumped graph's symbols."""

    def __init__(self, command, dump_path):
        self.dump = dump_path
        self.latest = {}
        self.lock = threading.Lock()
        self.process = subprocess.Popen(
            [*command, "--json-status", "--status-ms", "100", "--state-dir", "none", "--control-stdin",
             "--dump-json", dump_path],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.process.stdout:
            try:
                status = json.loads(line)
            except ValueError:
                continue
            with self.lock:
                self.latest = status

    def status(self):
        with self.lock:
            return dict(self.latest)

    def stop(self, timeout_s=30):
        """Ends the process as end of input does (it writes its dump), and returns the dumped graph's symbols."""
        if self.process.poll() is None:
            self.process.stdin.close()
            self.process.wait(timeout=timeout_s)
        with open(self.dump) as f:
            return json.load(f)["DSRModel"]["symbols"]

    def kill(self):
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        for stream in (self.process.stdin, self.process.stdout):
            if stream and not stream.closed:
                stream.close()
