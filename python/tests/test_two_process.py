"""A Python agent and `cortex agent` processes share one graph over RTPS on loopback: the Python agent joins the
graph a `cortex agent` started from the fixture, its writes reach that agent (node insert, attribute update), a
second `cortex agent`'s writes reach Python (node insert, attribute write) and fire Python's signals, and every
agent ends on the same graph digest. Every wait is on a condition with a deadline."""

import os
import queue
import unittest

from cortex_dsr import *  # noqa: F401,F403

import support


class CortexAgent(support.StatusProcess):
    """A `cortex agent` process on this test's topic, its JSON status lines read on a thread."""

    def __init__(self, binary, agent_id, prefix, workdir, extra=()):
        command = [binary, "agent", "--id", str(agent_id), "--domain", "0", "--topic-prefix", prefix, *extra]
        super().__init__(command, os.path.join(workdir, f"dump{agent_id}.json"))


@unittest.skipUnless(support.cortex_binary(), "the cortex binary is not built (cargo build -p harness --bin cortex)")
class PythonAndCortexAgents(unittest.TestCase):
    def setUp(self):
        self.fixture = support.Fixture()
        self.prefix = support.topic_prefix("pymp")
        self.agents = []
        self.graph = None

    def tearDown(self):
        if self.graph is not None:
            self.graph.close()
        for agent in self.agents:
            agent.kill()
        self.fixture.remove()

    def start_agent(self, agent_id, *extra):
        agent = CortexAgent(support.cortex_binary(), agent_id, self.prefix, self.fixture.dir, extra)
        self.agents.append(agent)
        return agent

    def test_a_python_agent_and_cortex_agents_share_one_graph(self):
        first = self.start_agent(1, "--seed-json", self.fixture.path, "--join-wait-ms", "500")
        support.wait_until(lambda: first.status().get("ready"), 60, "the first cortex agent to start its graph")
        self.assertEqual(first.status()["nodes"], 6)

        # The Python agent joins the running graph (no file: it must come from the cortex agent).
        self.graph = DSRGraph(0, "python", 7, topic_prefix=self.prefix, join_wait_ms=20000)
        g = self.graph
        self.assertEqual(g.get_node("root").attrs["color"].value, "blue")
        self.assertEqual(len(g.get_nodes()), 6)

        calls = queue.Queue()
        signals.connect(g, signals.UPDATE_NODE, lambda i, t: calls.put(("node", i, t)))
        signals.connect(g, signals.UPDATE_NODE_ATTR, lambda i, names: calls.put(("attrs", i, tuple(names))))

        # Python → cortex: an attribute update and a node insert.
        root = g.get_node("root")
        root.attrs["color"].value = "red"
        self.assertTrue(g.update_node(root))
        python_node = Node(7, "object", "from_python")
        python_node.attrs["pos_x"] = Attribute(1.5, 7)
        python_id = g.insert_node(python_node)
        self.assertIsNotNone(python_id)
        support.wait_until(lambda: first.status().get("nodes") == 7, 60, "the cortex agent to see Python's node")

        # cortex → Python: a second cortex agent joins and inserts a node with an attribute written after it.
        second = self.start_agent(2, "--join-wait-ms", "20000", "--insert-nodes", "1")
        node = support.wait_until(lambda: g.get_node("a2_0"), 60, "Python to see the second agent's node")
        support.wait_until(lambda: "pos_y" in g.get_node("a2_0").attrs, 60, "the second agent's attribute write")
        self.assertEqual(g.get_node("a2_0").attrs["pos_y"].value, 2.0)
        self.assertEqual(g.get_node("a2_0").attrs["pos_y"].agent_id, 2)

        # Python's signals fired for the remote insert and the remote attribute write.
        seen = set()

        def remote_signals_seen():
            while True:
                try:
                    seen.add(calls.get_nowait())
                except queue.Empty:
                    break
            return ("node", node.id, "object") in seen and any(
                c[0] == "attrs" and c[1] == node.id and "pos_y" in c[2] for c in seen)

        support.wait_until(remote_signals_seen, 30, "UPDATE_NODE and UPDATE_NODE_ATTR for the remote node")

        # Everyone on one graph: equal digests, then the cortex agent's dump holds Python's writes.
        support.wait_until(
            lambda: first.status().get("digest") == second.status().get("digest") == g.digest()
            and first.status().get("nodes") == 8,
            60, "equal digests on the three agents")
        symbols = first.stop()
        by_name = {s["name"]: s for s in symbols.values()}
        self.assertEqual(by_name["root"]["attribute"]["color"]["value"], "red")
        self.assertAlmostEqual(by_name["from_python"]["attribute"]["pos_x"]["value"], 1.5)
        second.stop()


if __name__ == "__main__":
    unittest.main()
