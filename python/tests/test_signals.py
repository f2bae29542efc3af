"""Signals: each kind pydsr offers fires with pydsr's arguments, on the agent's signal thread, and a callback may
read and write the graph without deadlocking it."""

import queue
import threading
import unittest

from cortex_dsr import *  # noqa: F401,F403

import support


class SignalCase(support.GraphTestCase):
    def setUp(self):
        super().setUp()
        self.calls = queue.Queue()

    def record(self, kind):
        def callback(*args):
            self.calls.put((kind, args, threading.current_thread() is threading.main_thread()))
        signals.connect(self.g, kind, callback)

    def next_call(self, kind, accept=lambda args: True, timeout_s=20.0):
        """The first recorded call of `kind` whose arguments `accept` takes, within the timeout."""
        deadline = support.time.monotonic() + timeout_s
        while True:
            remaining = deadline - support.time.monotonic()
            if remaining <= 0:
                self.fail(f"no {kind} signal within {timeout_s} s")
            try:
                got_kind, args, on_main = self.calls.get(timeout=remaining)
            except queue.Empty:
                continue
            if got_kind == kind and accept(args):
                self.assertFalse(on_main, "callbacks run on the signal thread")
                return args


class EachKindFires(SignalCase):
    def test_update_node_on_insert(self):
        self.record(signals.UPDATE_NODE)
        new_id = self.g.insert_node(Node(12, "mesh", "signalled"))
        self.assertEqual(self.next_call(signals.UPDATE_NODE, lambda a: a[0] == new_id), (new_id, "mesh"))

    def test_update_node_attr_lists_the_names_written_together(self):
        self.record(signals.UPDATE_NODE_ATTR)
        robot = self.g.get_node("robot")
        robot.attrs["pos_x"] = Attribute(1.0, 12)
        robot.attrs["pos_y"] = Attribute(2.0, 12)
        self.assertTrue(self.g.update_node(robot))
        node_id, names = self.next_call(signals.UPDATE_NODE_ATTR, lambda a: a[0] == 2)
        self.assertEqual(sorted(names), ["pos_x", "pos_y"])

    def test_an_attribute_update_also_signals_update_node_as_pydsr_does(self):
        self.record(signals.UPDATE_NODE)
        robot = self.g.get_node("robot")
        robot.attrs["pos_x"] = Attribute(1.0, 12)
        self.assertTrue(self.g.update_node(robot))
        self.assertEqual(self.next_call(signals.UPDATE_NODE), (2, "omnirobot"))

    def test_an_edge_attribute_update_also_signals_update_edge(self):
        self.record(signals.UPDATE_EDGE)
        edge = self.g.get_edge(1, 2, "RT")
        edge.attrs["rt_translation"] = Attribute([7.0, 0.0, 0.0], 12)
        self.assertTrue(self.g.insert_or_assign_edge(edge))
        self.assertEqual(self.next_call(signals.UPDATE_EDGE), (1, 2, "RT"))

    def test_update_edge_on_insert(self):
        self.record(signals.UPDATE_EDGE)
        self.assertTrue(self.g.insert_or_assign_edge(Edge(3, 1, "in", 12)))
        self.assertEqual(self.next_call(signals.UPDATE_EDGE), (1, 3, "in"))

    def test_update_edge_attr(self):
        self.record(signals.UPDATE_EDGE_ATTR)
        edge = self.g.get_edge(1, 2, "RT")
        edge.attrs["rt_translation"] = Attribute([5.0, 0.0, 0.0], 12)
        self.assertTrue(self.g.insert_or_assign_edge(edge))
        self.assertEqual(self.next_call(signals.UPDATE_EDGE_ATTR), (1, 2, "RT", ["rt_translation"]))

    def test_delete_edge(self):
        self.record(signals.DELETE_EDGE)
        self.assertTrue(self.g.delete_edge(2, 3, "RT"))
        self.assertEqual(self.next_call(signals.DELETE_EDGE), (2, 3, "RT"))

    def test_delete_node(self):
        self.record(signals.DELETE_NODE)
        self.assertTrue(self.g.delete_node("table"))
        self.assertEqual(self.next_call(signals.DELETE_NODE), (5,))

    def test_deleting_a_node_also_signals_its_edges(self):
        self.record(signals.DELETE_EDGE)
        self.assertTrue(self.g.delete_node("laser"))
        self.assertEqual(self.next_call(signals.DELETE_EDGE), (2, 3, "RT"))


class CallbacksAndTheGraph(SignalCase):
    def test_a_callback_that_reads_the_graph_does_not_deadlock(self):
        seen = queue.Queue()

        def on_node(node_id, node_type):
            node = self.g.get_node(node_id)  # the agent's read path, from the signal thread
            seen.put((node.name, node_type))

        signals.connect(self.g, signals.UPDATE_NODE, on_node)
        for i in range(20):
            self.g.insert_node(Node(12, "mesh", f"reader_{i}"))
        names = {seen.get(timeout=20)[0] for _ in range(20)}
        self.assertEqual(names, {f"reader_{i}" for i in range(20)})

    def test_a_callback_may_write_the_graph(self):
        done = threading.Event()

        def on_node(node_id, node_type):
            if node_type == "mesh":
                node = self.g.get_node(node_id)
                node.attrs["pos_x"] = Attribute(42.0, 12)
                self.g.update_node(node)
                done.set()

        signals.connect(self.g, signals.UPDATE_NODE, on_node)
        new_id = self.g.insert_node(Node(12, "mesh", "writer"))
        self.assertTrue(done.wait(20))
        support.wait_until(lambda: "pos_x" in self.g.get_node(new_id).attrs, what="the callback's write")

    def test_an_exception_in_a_callback_does_not_stop_the_signals(self):
        def broken(node_id, node_type):
            raise ValueError("a broken callback (expected in this test)")

        signals.connect(self.g, signals.UPDATE_NODE, broken)
        self.record(signals.UPDATE_NODE)
        first = self.g.insert_node(Node(12, "mesh", "first"))
        second = self.g.insert_node(Node(12, "mesh", "second"))
        self.next_call(signals.UPDATE_NODE, lambda a: a[0] == first)
        self.next_call(signals.UPDATE_NODE, lambda a: a[0] == second)

    def test_several_callbacks_of_one_kind_all_fire(self):
        self.record(signals.DELETE_NODE)
        self.record(signals.DELETE_NODE)
        self.g.delete_node(5)
        self.next_call(signals.DELETE_NODE)
        self.next_call(signals.DELETE_NODE)

    def test_connect_checks_its_arguments(self):
        with self.assertRaises(TypeError):
            signals.connect(self.g, signals.UPDATE_NODE, "not callable")
        with self.assertRaises(TypeError):
            signals.connect(self.g, 3, lambda *a: None)


class Lifetime(unittest.TestCase):
    def test_a_graph_whose_callback_refers_to_it_is_collected(self):
        import gc
        import weakref
        fixture = support.Fixture()
        try:
            g = support.new_graph(fixture.path)
            signals.connect(g, signals.UPDATE_NODE, lambda node_id, node_type: g.get_node(node_id))
            alive = weakref.ref(g)
            del g
            gc.collect()
            self.assertIsNone(alive(), "the graph ↔ callback cycle was collected")
        finally:
            fixture.remove()


if __name__ == "__main__":
    unittest.main()
