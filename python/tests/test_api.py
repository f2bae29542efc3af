"""The pydsr API as cortex_dsr offers it: value objects, the graph, the RT and inner APIs.

The cases are those pydsr's own suite checks (construction, read-only and writable properties, the exceptions
of each misuse, graph reads and writes, RT edges and transforms), written here against a small fixture graph,
plus the value-type rules and the numpy arrays that pydsr's binding implies."""

import math
import os
import unittest

import numpy as np

from cortex_dsr import *  # noqa: F401,F403  (the way pydsr scripts import it)
import cortex_dsr

import support


class AttributeBehaviour(unittest.TestCase):
    def test_three_argument_form_keeps_timestamp_and_agent(self):
        a = Attribute(10.4, 0, 12)
        self.assertAlmostEqual(a.value, 10.4, 5)
        self.assertEqual(a.timestamp, 0)
        self.assertEqual(a.agent_id, 12)

    def test_two_argument_form_takes_the_agent_and_stamps_now(self):
        a = Attribute(10.4, 12)
        self.assertAlmostEqual(a.value, 10.4, 5)
        self.assertEqual(a.agent_id, 12)
        self.assertGreater(a.timestamp, 0)

    def test_value_keeps_its_type(self):
        a = Attribute(10.4, 0, 12)
        a.value = 0.0
        self.assertAlmostEqual(a.value, 0.0, 5)
        with self.assertRaises(TypeError):
            a.value = True
        with self.assertRaises(TypeError):
            a.value = "text"
        s = Attribute("blue", 0, 12)
        with self.assertRaises(TypeError):
            s.value = 3

    def test_agent_id_and_timestamp_are_read_only(self):
        a = Attribute(10.4, 0, 12)
        with self.assertRaises(AttributeError):
            a.agent_id = 100
        with self.assertRaises(AttributeError):
            a.timestamp = 100

    def test_an_assignment_restamps_the_attribute(self):
        a = Attribute(1.0, 0, 12)
        a.value = 2.0
        self.assertGreater(a.timestamp, 0)

    def test_python_values_take_pydsr_types(self):
        self.assertIsInstance(Attribute("x", 1).value, str)
        self.assertIs(Attribute(True, 1).value, True)
        self.assertEqual(Attribute(7, 1).value, 7)
        self.assertEqual(Attribute(-7, 1).value, -7)
        floats = Attribute([1.0, 2.0, 3.5], 1).value
        self.assertEqual(floats.dtype, np.float32)
        np.testing.assert_array_equal(floats, [1.0, 2.0, 3.5])
        small = Attribute([1, 2, 255], 1).value
        self.assertEqual(small.dtype, np.uint8)
        big = Attribute([1, 2, 1 << 40], 1).value
        self.assertEqual(big.dtype, np.uint64)
        raw = Attribute(b"\x00\x01\x02", 1).value
        self.assertEqual(raw.dtype, np.uint8)
        self.assertEqual(list(raw), [0, 1, 2])

    def test_numpy_arrays_become_vectors(self):
        image = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)
        a = Attribute(image, 1)
        self.assertEqual(a.value.dtype, np.uint8)
        np.testing.assert_array_equal(a.value, image.ravel())
        f = Attribute(np.array([0.5, 1.5], dtype=np.float32), 1)
        np.testing.assert_array_equal(f.value, [0.5, 1.5])
        u = Attribute(np.array([1, 2], dtype=np.uint64), 1)
        self.assertEqual(u.value.dtype, np.uint64)

    def test_unsupported_values_raise_type_error(self):
        with self.assertRaises(TypeError):
            Attribute(None, 1)
        with self.assertRaises(TypeError):
            Attribute({"a": 1}, 1)
        with self.assertRaises(TypeError):
            Attribute(np.array(["a"]), 1)


class EdgeBehaviour(unittest.TestCase):
    def test_constructor_takes_to_then_from(self):
        e = Edge(10, 11, "RT", 0)
        self.assertEqual(e.destination, 10)
        self.assertEqual(e.origin, 11)
        self.assertEqual(e.type, "RT")

    def test_type_and_ends_are_read_only(self):
        e = Edge(10, 11, "RT", 0)
        for name, value in (("type", "NOTYPE"), ("origin", 22), ("destination", 22)):
            with self.assertRaises(AttributeError):
                setattr(e, name, value)

    def test_agent_id_is_writable(self):
        e = Edge(10, 11, "RT", 0)
        self.assertEqual(e.agent_id, 0)
        e.agent_id = 22
        self.assertEqual(e.agent_id, 22)

    def test_an_unknown_edge_type_raises_runtime_error(self):
        with self.assertRaises(RuntimeError):
            Edge(10, 11, "no_such_edge_type", 0)

    def test_attrs_is_a_mutable_mapping(self):
        e = Edge(10, 11, "RT", 0)
        self.assertEqual(len(e.attrs), 0)
        e.attrs["test"] = Attribute(10.4, 0, 12)
        self.assertEqual(len(e.attrs), 1)
        self.assertIn("test", e.attrs)
        self.assertIsNotNone(e.attrs["test"])
        del e.attrs["test"]
        with self.assertRaises(KeyError):
            e.attrs["test"]
        with self.assertRaises(KeyError):
            del e.attrs["test"]
        import collections.abc
        self.assertIsInstance(e.attrs, collections.abc.MutableMapping)


class NodeBehaviour(unittest.TestCase):
    def test_known_types_only(self):
        self.assertIsNotNone(Node(1, "root"))
        with self.assertRaises(RuntimeError):
            Node(1, "test")

    def test_name_type_and_id_are_read_only(self):
        n = Node(1, "root", "name")
        self.assertEqual(n.name, "name")
        self.assertEqual(n.type, "root")
        self.assertEqual(n.id, 0)
        with self.assertRaises(AttributeError):
            n.name = "newname"
        with self.assertRaises(AttributeError):
            n.type = "world"
        with self.assertRaises(AttributeError):
            n.id = "newtype"

    def test_agent_id_is_writable(self):
        n = Node(1, "root", "name")
        self.assertEqual(n.agent_id, 1)
        n.agent_id = 2
        self.assertEqual(n.agent_id, 2)

    def test_attrs_store_copies_and_return_live_entries(self):
        n = Node(1, "root", "name")
        self.assertEqual(len(n.attrs), 0)
        a = Attribute(10.4, 0, 12)
        n.attrs["test"] = a
        a.value = 99.0  # the map holds a copy
        self.assertAlmostEqual(n.attrs["test"].value, 10.4, 5)
        n.attrs["test"].value = 1.5  # an entry is the map's own object
        self.assertAlmostEqual(n.attrs["test"].value, 1.5, 5)
        self.assertEqual(list(n.attrs), ["test"])
        self.assertEqual([k for k, _ in n.attrs.items()], ["test"])
        del n.attrs["test"]
        with self.assertRaises(KeyError):
            n.attrs["test"]

    def test_known_names_narrow_values_or_refuse_them(self):
        n = Node(1, "root", "name")
        n.attrs["pos_x"] = Attribute(1.5, 1)  # f32 by the dictionary
        self.assertAlmostEqual(n.attrs["pos_x"].value, 1.5)
        n.attrs["level"] = Attribute(3, 1)  # i32
        self.assertEqual(n.attrs["level"].value, 3)
        n.attrs["imu_angular_velocity"] = Attribute([1.0, 2.0, 3.0], 1)  # [f32; 3]
        self.assertEqual(len(n.attrs["imu_angular_velocity"].value), 3)
        with self.assertRaises(TypeError):
            n.attrs["pos_x"] = Attribute("not a float", 1)
        with self.assertRaises(TypeError):
            n.attrs["imu_angular_velocity"] = Attribute([1.0, 2.0], 1)

    def test_edges_map_is_keyed_by_destination_and_type(self):
        n = Node(1, "root", "name")
        self.assertEqual(len(n.edges), 0)
        n.edges[(11, "RT")] = Edge(10, 11, "RT", 0)
        self.assertEqual(len(n.edges), 1)
        self.assertIsNotNone(n.edges[(11, "RT")])
        del n.edges[(11, "RT")]
        with self.assertRaises(KeyError):
            n.edges[(11, "RT")]


class GraphCase(support.GraphTestCase):
    """One graph per test, started alone from the fixture on a topic of its own."""


class GraphReads(GraphCase):
    def test_get_node_by_id_and_by_name(self):
        self.assertIsNotNone(self.g.get_node(1))
        root = self.g.get_node("root")
        self.assertEqual((root.id, root.name, root.type), (1, "root", "root"))
        self.assertEqual(root.attrs["color"].value, "blue")
        self.assertIsNone(self.g.get_node(1000000))
        self.assertIsNone(self.g.get_node("weirdname"))
        with self.assertRaises(TypeError):
            self.g.get_node(1.5)
        with self.assertRaises(TypeError):
            self.g.get_node(-1)
        self.assertEqual(self.g.get_node(np.uint64(2)).name, "robot")

    def test_a_node_copy_lists_its_outgoing_edges(self):
        robot = self.g.get_node("robot")
        self.assertEqual(set(robot.edges.keys()), {(3, "RT"), (4, "RT")})
        self.assertEqual(robot.edges[(3, "RT")].origin, 2)

    def test_get_node_root(self):
        root = self.g.get_node_root()
        self.assertEqual((root.id, root.name), (1, "root"))

    def test_get_nodes_and_get_nodes_by_type(self):
        self.assertEqual(len(self.g.get_nodes()), 6)
        self.assertEqual(len(self.g.get_nodes_by_type("rgbd")), 1)
        self.assertEqual(len(self.g.get_nodes_by_type("invalidtype")), 0)

    def test_names_and_ids(self):
        self.assertEqual(self.g.get_name_from_id(1), "root")
        self.assertIsNone(self.g.get_name_from_id(11111111))
        self.assertEqual(self.g.get_id_from_name("root"), 1)
        self.assertIsNone(self.g.get_id_from_name("11111111"))

    def test_get_edge_by_ids_and_by_names(self):
        self.assertIsNotNone(self.g.get_edge(1, 2, "RT"))
        self.assertIsNotNone(self.g.get_edge(self.g.get_name_from_id(1), self.g.get_name_from_id(2), "RT"))
        self.assertIsNone(self.g.get_edge(11111, 22222, "RT"))
        self.assertIsNone(self.g.get_edge("11111", "22222", "RT"))

    def test_edges_by_type_and_to_a_node(self):
        self.assertEqual(len(self.g.get_edges_by_type("RT")), 4)
        self.assertEqual(len(self.g.get_edges_by_type("invalidtype")), 0)
        self.assertEqual([(e.origin, e.destination) for e in self.g.get_edges_to_id(2)], [(1, 2)])
        self.assertEqual(len(self.g.get_edges_to_id(1)), 0)

    def test_attributes_read_from_the_graph_carry_writer_and_stamp(self):
        color = self.g.get_node("root").attrs["color"]
        self.assertEqual(color.agent_id, 12)
        self.assertGreater(color.timestamp, 0)

    def test_write_to_json_file_round_trips(self):
        out = os.path.join(self.fixture.dir, "out.json")
        self.g.write_to_json_file(out)
        g2 = support.new_graph(out, agent_id=13)
        try:
            self.assertEqual(len(g2.get_nodes()), 6)
        finally:
            g2.close()


class GraphWrites(GraphCase):
    def test_insert_node_returns_the_id_and_sets_it(self):
        node = Node(12, "mesh", "newmesh")
        node.attrs["pos_x"] = Attribute(3.0, 12)
        new_id = self.g.insert_node(node)
        self.assertIsNotNone(new_id)
        self.assertEqual(node.id, new_id)
        stored = self.g.get_node("newmesh")
        self.assertEqual(stored.id, new_id)
        self.assertAlmostEqual(stored.attrs["pos_x"].value, 3.0)

    def test_insert_node_with_a_taken_name_returns_none(self):
        self.assertIsNone(self.g.insert_node(Node(12, "mesh", "root")))

    def test_insert_node_without_a_name_gets_one(self):
        node = Node(12, "mesh")
        new_id = self.g.insert_node(node)
        self.assertIsNotNone(new_id)
        self.assertTrue(self.g.get_node(new_id).name.startswith("mesh_"))

    def test_update_node_writes_changed_attributes(self):
        root = self.g.get_node("root")
        root.attrs["color"].value = "red"
        self.assertTrue(self.g.update_node(root))
        self.assertEqual(self.g.get_node("root").attrs["color"].value, "red")

    def test_update_node_adds_and_removes_attributes(self):
        robot = self.g.get_node("robot")
        robot.attrs["pos_y"] = Attribute(7.0, 12)
        del robot.attrs["level"]
        self.assertTrue(self.g.update_node(robot))
        again = self.g.get_node("robot")
        self.assertAlmostEqual(again.attrs["pos_y"].value, 7.0)
        self.assertNotIn("level", again.attrs)

    def test_update_node_of_a_deleted_node_returns_false(self):
        table = self.g.get_node("table")
        self.assertTrue(self.g.delete_node("table"))
        self.assertFalse(self.g.update_node(table))

    def test_a_new_attribute_name_is_registered_with_its_first_type_and_other_types_refused(self):
        # As pydsr: the first write of a name no dictionary knows registers it with that value's type; from then on
        # a value of another type is refused (TypeError when stored in a node's attributes, as pydsr does).
        robot = self.g.get_node("robot")
        robot.attrs["an_attribute_no_dictionary_knows"] = Attribute(1.0, 12)
        self.assertTrue(self.g.update_node(robot))
        self.assertIn("an_attribute_no_dictionary_knows", self.g.get_node("robot").attrs)
        robot = self.g.get_node("robot")
        with self.assertRaises(TypeError) as raised:
            robot.attrs["an_attribute_no_dictionary_knows"] = Attribute("text", 12)
        self.assertIn("an_attribute_no_dictionary_knows", str(raised.exception))
        stored = self.g.get_node("robot").attrs["an_attribute_no_dictionary_knows"].value
        self.assertAlmostEqual(stored, 1.0)

    def test_delete_node_by_id_and_by_name(self):
        self.assertIsNotNone(self.g.get_node(1))
        self.assertTrue(self.g.delete_node(1))
        self.assertIsNone(self.g.get_node(1))
        self.assertTrue(self.g.delete_node("table"))
        self.assertFalse(self.g.delete_node("table"))
        self.assertFalse(self.g.delete_node(123456))

    def test_deleting_a_node_removes_its_edges(self):
        self.assertTrue(self.g.delete_node("robot"))
        self.assertIsNone(self.g.get_edge(1, 2, "RT"))
        self.assertEqual(len(self.g.get_edges_to_id(3)), 0)

    def test_insert_or_assign_edge_updates_then_inserts(self):
        edge = self.g.get_edge(1, 2, "RT")
        edge.attrs["color"] = Attribute("red", 0, 12)
        self.assertTrue(self.g.insert_or_assign_edge(edge))
        self.assertEqual(self.g.get_edge(1, 2, "RT").attrs["color"].value, "red")
        self.assertTrue(self.g.insert_or_assign_edge(Edge(1, 2, "in", 12)))
        self.assertIsNotNone(self.g.get_edge(2, 1, "in"))
        self.assertFalse(self.g.insert_or_assign_edge(Edge(1, 999999, "in", 12)))

    def test_delete_edge(self):
        self.assertIsNotNone(self.g.get_edge(1, 2, "RT"))
        self.assertTrue(self.g.delete_edge(1, 2, "RT"))
        self.assertIsNone(self.g.get_edge(1, 2, "RT"))
        self.assertFalse(self.g.delete_edge(111111, 22222, "RT"))
        self.assertTrue(self.g.delete_edge("robot", "laser", "RT"))

    def test_images_round_trip_through_the_graph_as_numpy(self):
        camera = self.g.get_node("camera")
        frame = (np.arange(480 * 640 * 3) % 251).astype(np.uint8).reshape(480, 640, 3)
        camera.attrs["cam_rgb"] = Attribute(frame, 12)
        self.assertTrue(self.g.update_node(camera))
        back = self.g.get_node("camera").attrs["cam_rgb"].value
        self.assertEqual(back.dtype, np.uint8)
        self.assertEqual(back.shape, (480 * 640 * 3,))
        np.testing.assert_array_equal(back.reshape(480, 640, 3), frame)

    def test_a_closed_graph_raises_runtime_error(self):
        self.g.close()
        with self.assertRaises(RuntimeError):
            self.g.get_node(1)


class GraphStart(unittest.TestCase):
    def test_a_missing_file_raises_runtime_error(self):
        with self.assertRaises(RuntimeError):
            support.new_graph("/nonexistent/graph.json")

    def test_a_file_the_graph_refuses_raises_runtime_error_naming_the_place(self):
        import json
        import tempfile
        # Two symbols with one name: refused leniently too (a link to a missing node would only be skipped).
        graph = support.fixture_graph()
        symbols = graph["DSRModel"]["symbols"]
        taken = next(symbol["name"] for key, symbol in symbols.items() if key != "203")
        symbols["203"]["name"] = taken
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            json.dump(graph, f)
        try:
            with self.assertRaises(RuntimeError) as raised:
                support.new_graph(f.name)
            self.assertIn("cannot seed the graph", str(raised.exception))
            self.assertIn("already taken", str(raised.exception))
        finally:
            os.unlink(f.name)

    def test_an_agent_id_out_of_range_raises_runtime_error(self):
        with self.assertRaises(RuntimeError):
            support.new_graph("", agent_id=5000)

    def test_without_a_file_or_peer_the_graph_starts_empty(self):
        g = support.new_graph("")
        try:
            self.assertEqual(g.get_nodes(), [])
        finally:
            g.close()

    def test_a_real_cortex_world_graph_loads(self):
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        path = os.path.join(root, "datasets", "cortex-graphs", "autonomyLab_complete.json")
        g = support.new_graph(path)
        try:
            self.assertEqual(len(g.get_nodes()), 81)
            self.assertIsNotNone(g.get_node("world"))
            self.assertIsNotNone(inner_api(g).transform("world", "laser"))
        finally:
            g.close()

    def test_a_graph_of_another_era_loads_and_its_own_types_and_names_are_writable(self):
        # shadow_beta.json stores battery_load as a float (the built-in dictionary says i32) and has node types
        # (grid, servo) the built-in dictionary does not know: both load, and a script writes them as pydsr would.
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        g = support.new_graph(os.path.join(root, "datasets", "cortex-graphs", "shadow_beta.json"))
        try:
            battery = next(n for n in g.get_nodes() if "battery_load" in n.attrs)
            battery.attrs["battery_load"] = Attribute(55.5, 12)
            self.assertTrue(g.update_node(battery))
            self.assertAlmostEqual(g.get_node(battery.id).attrs["battery_load"].value, 55.5)
            grid = g.get_nodes_by_type("grid")[0]
            self.assertIsNotNone(g.insert_node(Node(12, "grid", "second_grid")))
            self.assertEqual(len(g.get_nodes_by_type("grid")), 2, grid.name)
            with self.assertRaises(RuntimeError):
                Node(12, "spaceship", "s1")
        finally:
            g.close()


class RtApi(GraphCase):
    def test_insert_or_assign_edge_rt_adds_an_rt_edge(self):
        rt = rt_api(self.g)
        root = self.g.get_node("root")
        rt.insert_or_assign_edge_RT(root, 203, [0.0, 1.2, 0.0], [1.1, 0.0, 2.2])
        root = self.g.get_node("root")
        self.assertIsNotNone(root.edges[(203, "RT")])
        self.assertEqual(self.g.get_node(203).attrs["parent"].value, 1)

    def test_insert_or_assign_edge_rt_to_a_missing_node_raises_runtime_error(self):
        with self.assertRaises(RuntimeError):
            rt_api(self.g).insert_or_assign_edge_RT(self.g.get_node("root"), 424242, [0.0] * 3, [0.0] * 3)

    def test_get_edge_rt(self):
        edge = rt_api(self.g).get_edge_RT(self.g.get_node("root"), 2)
        self.assertEqual(edge.type, "RT")
        self.assertIsNone(rt_api(self.g).get_edge_RT(self.g.get_node("root"), 3))

    def test_get_rt_pose_from_parent(self):
        pose = rt_api(self.g).get_RT_pose_from_parent(self.g.get_node(2))
        self.assertEqual(pose.shape, (4, 4))
        np.testing.assert_allclose(pose[:3, 3], [1000.0, 0.0, 0.0])
        self.assertIsNone(rt_api(self.g).get_RT_pose_from_parent(self.g.get_node(1)))

    def test_get_edge_rt_as_rtmat(self):
        rt = rt_api(self.g)
        edge = rt.get_edge_RT(self.g.get_node("root"), 5)
        with_stamp = rt.get_edge_RT_as_rtmat(edge, 0)
        without = rt.get_edge_RT_as_rtmat(edge)
        np.testing.assert_allclose(with_stamp, without)
        np.testing.assert_allclose(with_stamp[:3, 3], [0.0, 2000.0, 0.0])
        np.testing.assert_allclose(with_stamp[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-6)
        self.assertIsNone(rt.get_edge_RT_as_rtmat(Edge(2, 1, "RT", 0)))

    def test_get_translation(self):
        rt = rt_api(self.g)
        np.testing.assert_allclose(rt.get_translation(1, 2, 0), [1000.0, 0.0, 0.0])
        np.testing.assert_allclose(rt.get_translation(1, 2), [1000.0, 0.0, 0.0])
        self.assertIsNone(rt.get_translation(1, 3))


class InnerApi(GraphCase):
    def test_transform_of_a_frame_origin_and_of_a_point(self):
        inner = inner_api(self.g)
        # The laser sits 300 mm above the robot, which is 1000 mm along x from the root.
        np.testing.assert_allclose(inner.transform("root", "laser", 0), [1000.0, 0.0, 300.0])
        np.testing.assert_allclose(inner.transform("root", [1.0, 2.0, 3.0], "laser", 0), [1001.0, 2.0, 303.0])
        np.testing.assert_allclose(inner.transform("laser", "root"), [-1000.0, 0.0, -300.0])
        self.assertIsNone(inner.transform("root", "mesh_203"))
        self.assertIsNone(inner.transform("root", "no_such_node"))

    def test_transform_axis(self):
        inner = inner_api(self.g)
        np.testing.assert_allclose(inner.transform_axis("root", "laser", 0), [1000.0, 0.0, 300.0, 0, 0, 0], atol=1e-9)
        moved = inner.transform_axis("root", [1.0, 0.0, 0.0, 0.0, 0.0, 0.5], "table", 0)
        np.testing.assert_allclose(moved[:3], [0.0, 2001.0, 0.0], atol=1e-3)
        self.assertAlmostEqual(moved[5], 0.5 + math.pi / 2, 5)

    def test_matrices_and_angles(self):
        inner = inner_api(self.g)
        m = inner.get_transformation_matrix("root", "table")
        self.assertEqual(m.shape, (4, 4))
        np.testing.assert_allclose(inner.get_rotation_matrix("root", "table", 0), m[:3, :3])
        np.testing.assert_allclose(inner.get_translation_vector("root", "table", 0), [0.0, 2000.0, 0.0])
        np.testing.assert_allclose(inner.get_euler_xyz_angles("root", "table", 0), [0.0, 0.0, math.pi / 2], atol=1e-6)

    def test_results_follow_graph_changes(self):
        inner = inner_api(self.g)
        rt = rt_api(self.g)
        rt.insert_or_assign_edge_RT(self.g.get_node("robot"), 3, [0.0, 0.0, 500.0], [0.0, 0.0, 0.0])
        np.testing.assert_allclose(inner.transform("root", "laser"), [1000.0, 0.0, 500.0])


class Concurrency(unittest.TestCase):
    def test_other_python_threads_run_while_a_graph_waits_for_its_join(self):
        import threading
        ticks = []
        stop = threading.Event()

        def ticker():
            while not stop.is_set():
                ticks.append(1)
                stop.wait(0.005)

        thread = threading.Thread(target=ticker)
        thread.start()
        try:
            before = len(ticks)
            g = support.new_graph("", join_wait_ms=500)  # waits 500 ms for a peer, the GIL released
            during = len(ticks) - before
            g.close()
        finally:
            stop.set()
            thread.join()
        self.assertGreater(during, 10, "the ticker thread ran while DSRGraph() waited")

    def test_reprs_describe_the_objects(self):
        n = Node(1, "root", "described")
        n.attrs["pos_x"] = Attribute(1.0, 1)
        n.edges[(2, "RT")] = Edge(2, 0, "RT", 1)
        text = repr(n)
        self.assertIn("described", text)
        self.assertIn("pos_x", text)
        self.assertIn("Edge type: RT", text)
        self.assertIn("RT", repr(Edge(2, 1, "RT", 0)))


class Module(unittest.TestCase):
    def test_star_import_names(self):
        for name in ("Attribute", "Node", "Edge", "DSRGraph", "rt_api", "inner_api", "signals"):
            self.assertTrue(hasattr(cortex_dsr, name), name)


if __name__ == "__main__":
    unittest.main()
