//! CORTEX JSON against real and broken files: the five graphs of the C++ implementation must survive
//! parse → import → export → parse bit for bit, every malformed fixture must be refused with a message that names
//! the place, a refused import must leave the replica as it was, and no mutation of a real file may panic.

use dsr::Numbers;
use std::collections::BTreeMap;
use std::path::PathBuf;

use dsr::json::{self, Attributes, CortexGraph, CortexNode, JsonError, JsonWarning, Strictness};
use dsr::{Dictionary, EdgeKey, NodeId, Replica, ReplicaId, Value};
use proptest::prelude::*;

/// The five real graphs with their node and edge counts (as in datasets/cortex-graphs/README.md).
const REAL_GRAPHS: [(&str, usize, usize); 5] = [
    ("initial_dsr2.json", 75, 74),
    ("autonomyLab_complete.json", 81, 80),
    ("giraff_dsr.json", 62, 61),
    ("Robot_viriato.json", 14, 13),
    ("shadow_scene.json", 2, 1),
];

/// Real graphs from other robocomp repositories (datasets/cortex-graphs/README.md), each of a different shape:
/// file, nodes and edges imported, warnings of the lenient read and import.
const WILD_GRAPHS: [(&str, usize, usize, usize); 12] = [
    ("autonomyLab_objects.simscene.json", 41, 43, 11),
    ("sala_beta.json", 17, 16, 2),
    ("autonomyLab2.json", 31, 30, 4),
    ("furniture.json", 30, 28, 1),
    ("initial_dsr2_etc.json", 4, 3, 15),
    ("Robot_giraff.json", 10, 9, 1),
    ("conversationalAgent.json", 19, 20, 16),
    ("autonomyLab_Residencia_giraff.json", 199, 198, 3),
    ("shadow_beta.json", 19, 18, 8),
    ("floor_dnn_world.json", 12, 11, 10),
    ("active_inference_shadow.json", 8, 7, 10),
    ("shadow_test_guide.json", 23, 23, 30),
];

fn dataset(name: &str) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../datasets/cortex-graphs").join(name);
    std::fs::read(&path).unwrap_or_else(|error| panic!("cannot read {}: {error}", path.display()))
}

fn fixture(name: &str) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/json").join(name);
    std::fs::read(&path).unwrap_or_else(|error| panic!("cannot read {}: {error}", path.display()))
}

/// Parses and imports strictly into a fresh replica with the built-in dictionary.
fn load(bytes: &[u8], replica_id: u32) -> Result<Replica, JsonError> {
    let graph = json::parse_bytes(bytes)?;
    let mut replica = Replica::new(ReplicaId(replica_id));
    graph.import_with(&mut replica, 1_000, Strictness::Strict)?;
    Ok(replica)
}

/// Reads and imports leniently into a fresh replica with the built-in dictionary; returns the replica and every
/// warning of the read and the import.
fn load_lenient(bytes: &[u8]) -> Result<(Replica, Vec<JsonWarning>), JsonError> {
    let reading = json::read(bytes, Strictness::Lenient)?;
    let mut replica = Replica::new(ReplicaId(1));
    let report = reading.graph.import_into(&mut replica, 1_000)?;
    Ok((replica, reading.warnings.into_iter().chain(report.warnings).collect()))
}

#[test]
fn real_graphs_round_trip_bit_for_bit() {
    for (name, nodes, edges) in REAL_GRAPHS {
        let original = json::parse_bytes(&dataset(name)).unwrap_or_else(|error| panic!("{name}: {error}"));
        assert_eq!((original.nodes.len(), original.edges.len()), (nodes, edges), "{name}: counts");

        let mut first = Replica::new(ReplicaId(1));
        let report = original.import_into(&mut first, 1_000).unwrap_or_else(|error| panic!("{name}: {error}"));
        assert_eq!((report.nodes, report.edges, report.deltas.len()), (nodes, edges, nodes + edges), "{name}");
        let attributes: usize = original.nodes.values().map(|node| node.attrs.len()).sum::<usize>()
            + original.edges.values().map(BTreeMap::len).sum::<usize>();
        assert_eq!(report.attributes, attributes, "{name}: attribute count");
        assert_eq!((first.node_count(), first.edge_count()), (nodes, edges), "{name}: replica counts");

        let written = json::export(&first).unwrap_or_else(|error| panic!("{name}: export: {error}"));
        assert!(
            written.starts_with("{\n    \"DSRModel\": {\n        \"symbols\": {\n            \""),
            "{name}: layout"
        );
        let reread = json::parse(&written).unwrap_or_else(|error| panic!("{name}: reread: {error}"));
        assert_eq!(reread, original, "{name}: graph changed in the round trip");

        // The digest covers each value's writer and stamp, so the second import uses the same replica id and time.
        let second = load(written.as_bytes(), 1).unwrap_or_else(|error| panic!("{name}: reimport: {error}"));
        assert_eq!(second.digest(), first.digest(), "{name}: digests differ");
        assert_eq!(json::export(&second).unwrap(), written, "{name}: export is not deterministic");
        assert_eq!(CortexGraph::from_replica(&second), original, "{name}: replica view differs");
    }
}

#[test]
fn real_graph_quirks_are_read_as_written() {
    // Robot_viriato: ids, link ends and u64 values as strings; f32 as f64-then-narrowed.
    let viriato = json::parse_bytes(&dataset("Robot_viriato.json")).unwrap();
    let mind = &viriato.nodes[&NodeId(1000)];
    assert_eq!(mind.attrs["parent"], Value::U64(200));
    assert_eq!(mind.attrs["pos_x"], Value::F32(-278.689453f64 as f32));
    assert_eq!(mind.attrs["mass"], Value::I32(2));
    // shadow_scene: u64 as a JSON number, floats written as integers, ids as strings.
    let shadow = json::parse_bytes(&dataset("shadow_scene.json")).unwrap();
    assert_eq!(shadow.nodes[&NodeId(200)].attrs["parent"], Value::U64(100));
    assert_eq!(shadow.nodes[&NodeId(200)].attrs["base_target_x"], Value::F32(3600.0));
    let rt = &shadow.edges[&EdgeKey::new(NodeId(100), NodeId(200), "RT")];
    assert_eq!(rt["rt_translation"], Value::VecF32(Numbers::from([0.0f32, 0.0, 0.0])));
    // giraff: ids beyond 2^53 are kept exactly.
    let giraff = json::parse_bytes(&dataset("giraff_dsr.json")).unwrap();
    let largest = giraff.nodes.keys().next_back().unwrap().0;
    assert!(largest > 1 << 53, "largest id {largest}");
    assert!(json::export(&load(&dataset("giraff_dsr.json"), 1).unwrap()).unwrap().contains(&format!("\"{largest}\"")));
    // initial_dsr2: legacy edge attribute names.
    let initial = json::parse_bytes(&dataset("initial_dsr2.json")).unwrap();
    assert!(initial.edges.values().any(|attrs| attrs.contains_key("translation")));
    assert!(initial.edges.values().any(|attrs| attrs.contains_key("rotation_euler_xyz")));
}

#[test]
fn real_graphs_have_one_rt_tree_whose_depth_matches_the_level_attribute() {
    for (name, _, _) in REAL_GRAPHS {
        let graph = json::parse_bytes(&dataset(name)).unwrap();
        let analysis = graph.analyze();
        assert!(analysis.dangling_links.is_empty(), "{name}: {:?}", analysis.dangling_links);
        assert!(analysis.rt_cycles.is_empty(), "{name}: {:?}", analysis.rt_cycles);
        assert!(analysis.several_rt_parents.is_empty(), "{name}: {:?}", analysis.several_rt_parents);
        assert_eq!(analysis.rt_roots.len(), 1, "{name}: roots {:?}", analysis.rt_roots);
        let deepest_level = graph
            .nodes
            .values()
            .filter_map(|node| match node.attrs.get("level") {
                Some(Value::I32(level)) => Some(*level as usize),
                _ => None,
            })
            .max()
            .unwrap();
        let root_level = match graph.nodes[&analysis.rt_roots[0]].attrs.get("level") {
            Some(Value::I32(level)) => *level as usize,
            _ => 0,
        };
        assert_eq!(analysis.rt_depth, deepest_level - root_level, "{name}");
        assert_eq!(analysis.nodes, graph.nodes.len());
        assert_eq!(analysis.node_types.values().sum::<usize>(), graph.nodes.len());
        assert_eq!(analysis.edge_labels.values().sum::<usize>(), graph.edges.len());
        let by_name: usize = analysis.attribute_names.iter().map(|count| count.on_nodes + count.on_edges).sum();
        let by_type: usize = analysis.attribute_types.iter().map(|count| count.count).sum();
        assert_eq!((by_name, by_type), (analysis.attributes, analysis.attributes), "{name}");
    }
}

/// Each malformed fixture with the parts its error message must contain.
const MALFORMED: &[(&str, &[&str])] = &[
    ("syntax_error.json", &["json syntax error at line 47 column", "expected `,` or `}`"]),
    ("truncated.json", &["json syntax error at line", "EOF"]),
    ("trailing_data.json", &["json syntax error at line 67 column 1", "trailing characters"]),
    ("invalid_utf8.json", &["json syntax error at line", "unicode"]),
    ("not_an_object.json", &["document: expected an object, found an array of 1 items"]),
    ("missing_dsrmodel.json", &["document: missing field \"DSRModel\""]),
    ("missing_name.json", &["DSRModel.symbols[\"12\"]: missing field \"name\""]),
    ("missing_link_label.json", &["DSRModel.symbols[\"1\"].links[0]: missing field \"label\""]),
    ("missing_value.json", &["DSRModel.symbols[\"12\"].attribute[\"level\"]: missing field \"value\""]),
    ("links_not_array.json", &["DSRModel.symbols[\"12\"].links: expected an array, found an object"]),
    ("wrong_type_code.json", &["DSRModel.symbols[\"12\"].attribute[\"level\"].type: unknown attribute type code 14"]),
    ("string_type_code.json", &["DSRModel.symbols[\"12\"].attribute[\"level\"].type: expected an integer type code"]),
    ("string_for_int32.json", &["DSRModel.symbols[\"12\"].attribute[\"level\"].value: expected an integer", "\"one\""]),
    ("int32_out_of_range.json", &["attribute[\"level\"].value: the number 3000000000 is out of the i32 range"]),
    ("float_for_int32.json", &["attribute[\"level\"].value: expected an integer, found the number 1.5"]),
    ("float3_two_items.json", &["attribute[\"pose_translation\"].value: a [f32; 3] needs 3 numbers, found 2"]),
    ("uint64_not_a_number.json", &["attribute[\"parent\"].value: \"12a\" is not a u64 written in decimal digits"]),
    ("uint64_negative.json", &["attribute[\"parent\"].value: the number -1 is out of the u64 range"]),
    ("float32_out_of_range.json", &["attribute[\"pos_x\"].value: ", "is out of the f32 range"]),
    ("bool_as_number.json", &["attribute[\"collidable\"].value: expected true or false, found the number 1"]),
    (
        "vector_item_not_number.json",
        &["DSRModel.symbols[\"1\"].links[0].linkAttribute[\"rt_translation\"].value[1]: expected a number"],
    ),
    ("key_differs_from_id.json", &["DSRModel.symbols[\"12\"]: symbol key \"12\" differs from its id 13"]),
    ("duplicate_id.json", &["DSRModel.symbols[\"012\"].id: node id 12 is used by more than one symbol"]),
    ("duplicate_symbol_key.json", &["DSRModel.symbols[\"12\"].id: node id 12 is used by more than one symbol"]),
    ("duplicate_attribute.json", &["DSRModel.symbols[\"12\"].attribute: key \"pos_x\" appears more than once"]),
    ("zero_id.json", &["DSRModel.symbols[\"0\"].id: node id 0 is reserved"]),
    ("negative_id.json", &["DSRModel.symbols[\"12\"].id: node id \"-12\" is not a decimal number"]),
    ("link_src_differs.json", &["DSRModel.symbols[\"1\"].links[0].src: link src 12 is not the symbol it is listed"]),
    ("duplicate_link.json", &["DSRModel.symbols[\"1\"].links[1]: link 1-[RT]->12 is listed more than once"]),
    // Import-time errors: the file is well-formed but cannot go into a replica.
    (
        "dangling_dst.json",
        &["DSRModel.symbols[\"1\"].links[dst=99, label=\"RT\"].dst: node 99 does not exist in the file or the replica"],
    ),
    ("duplicate_name.json", &["DSRModel.symbols[\"12\"].name: node name \"world\" is already taken by symbol 1"]),
    ("invalid_name.json", &["DSRModel.symbols[\"12\"].name: invalid node name \"robot#2\""]),
    (
        "unknown_attribute.json",
        &["DSRModel.symbols[\"12\"].attribute[\"favourite_colour\"]: unknown attribute name \"favourite_colour\""],
    ),
    (
        "attribute_type_conflict.json",
        &["DSRModel.symbols[\"12\"].attribute[\"pos_x\"]: attribute \"pos_x\" has type f32"],
    ),
    ("unknown_node_type.json", &["DSRModel.symbols[\"12\"].type: unknown node type \"spaceship\""]),
];

/// Fixtures that only the strict rules refuse: what the lenient ones do instead, as warnings naming the place.
const LENIENT: &[(&str, &[&str])] = &[
    ("float_for_int32.json", &["attribute[\"level\"].value: the number 1.5 is rounded to 2 (i32)"]),
    (
        "duplicate_attribute_same_value.json",
        &["symbols[\"12\"].attribute: key \"pos_x\" appears twice with the same value"],
    ),
    ("link_src_differs.json", &["links[0].src: the link is listed under symbol 1 but starts at 12; read as 12's"]),
    (
        "dangling_dst.json",
        &["links[dst=99, label=\"RT\"].dst: node 99 does not exist in the file or the replica: the link is skipped"],
    ),
    (
        "unknown_attribute.json",
        &[
            "attribute[\"favourite_colour\"]: unknown attribute name \"favourite_colour\" joins this graph's dictionary as string",
        ],
    ),
    (
        "attribute_type_conflict.json",
        &["attribute[\"pos_x\"]: attribute \"pos_x\" has type", "and f32 in the dictionary: kept as"],
    ),
    (
        "unknown_node_type.json",
        &["symbols[\"12\"].type: unknown node type \"spaceship\" joins this graph's dictionary"],
    ),
];

/// The lenient rules accept each of these with the warnings listed, and what they accept round-trips: written
/// and read again it is the same graph, with no conversion warning the second time.
#[test]
fn lenient_loading_accepts_what_the_cpp_loader_does_and_says_so() {
    for (name, expected) in LENIENT {
        let (replica, warnings) = load_lenient(&fixture(name)).unwrap_or_else(|error| panic!("{name}: {error}"));
        let text: Vec<String> = warnings.iter().map(ToString::to_string).collect();
        for part in *expected {
            assert!(text.iter().any(|warning| warning.contains(part)), "{name}: warnings {text:?} lack {part:?}");
        }
        let written = json::export(&replica).unwrap();
        let (again, warnings) = load_lenient(written.as_bytes()).unwrap();
        assert_eq!(again.digest(), replica.digest(), "{name}: the round trip changed the graph");
        let conversions: Vec<&JsonWarning> = warnings.iter().filter(|w| !w.what.contains("dictionary")).collect();
        assert!(conversions.is_empty(), "{name}: written back, it still needs conversions: {conversions:?}");
    }
}

/// Every real graph of the wild loads leniently with the warnings counted, and round-trips: what is written back
/// is what was read (same type codes and values), less the links a missing end made the import skip.
#[test]
fn real_graphs_of_every_era_load_leniently_and_round_trip() {
    for (name, nodes, edges, warning_count) in WILD_GRAPHS {
        let reading = json::read(&dataset(name), Strictness::Lenient).unwrap_or_else(|error| panic!("{name}: {error}"));
        let mut replica = Replica::new(ReplicaId(1));
        let report = reading.graph.import_into(&mut replica, 1_000).unwrap_or_else(|error| panic!("{name}: {error}"));
        assert_eq!((replica.node_count(), replica.edge_count()), (nodes, edges), "{name}: counts");
        assert_eq!(reading.warnings.len() + report.warnings.len(), warning_count, "{name}: warnings");

        let mut expected = reading.graph.clone();
        expected.edges.retain(|key, _| expected.nodes.contains_key(&key.from) && expected.nodes.contains_key(&key.to));
        let written = json::export(&replica).unwrap();
        let again = json::read(written.as_bytes(), Strictness::Lenient).unwrap();
        assert!(again.warnings.is_empty(), "{name}: written back, it needs conversions: {:?}", again.warnings);
        assert_eq!(again.graph, expected, "{name}: the round trip changed the graph");
    }
}

#[test]
fn malformed_files_are_refused_with_the_place_named() {
    for (name, expected) in MALFORMED {
        let message = match load(&fixture(name), 1) {
            Ok(_) => panic!("{name}: accepted"),
            Err(error) => error.to_string(),
        };
        for part in *expected {
            assert!(message.contains(part), "{name}: message {message:?} lacks {part:?}");
        }
        assert!(!message.contains('\n'), "{name}: message spans lines: {message:?}");
    }
}

#[test]
fn every_fixture_is_tested() {
    let mut listed: Vec<&str> = MALFORMED.iter().map(|(name, _)| *name).collect();
    listed.extend(["valid_small.json", "bom_valid.json", "duplicate_attribute_same_value.json"]);
    listed.sort_unstable();
    let directory = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/json");
    let mut present: Vec<String> =
        std::fs::read_dir(directory).unwrap().map(|entry| entry.unwrap().file_name().into_string().unwrap()).collect();
    present.sort_unstable();
    assert_eq!(present, listed);
}

#[test]
fn syntax_errors_carry_line_and_column() {
    let error = json::parse_bytes(&fixture("syntax_error.json")).unwrap_err();
    let JsonError::Syntax { line, column, .. } = error else { panic!("not a syntax error: {error}") };
    assert_eq!((line, column), (47, 17));
}

#[test]
fn a_byte_order_mark_is_skipped() {
    let with_mark = json::parse_bytes(&fixture("bom_valid.json")).unwrap();
    assert_eq!(with_mark, json::parse_bytes(&fixture("valid_small.json")).unwrap());
    assert_eq!(with_mark.nodes.len(), 2);
}

/// Strictly, an unknown name is refused; leniently it joins the graph's dictionary, so that local calls may use
/// it, while a name neither the built-in dictionary nor the graph knows is still refused.
#[test]
fn unknown_names_from_a_file_join_the_graphs_dictionary() {
    let graph = json::parse_bytes(&fixture("unknown_attribute.json")).unwrap();
    let mut strict = Replica::new(ReplicaId(1));
    let error = graph.import_with(&mut strict, 1, Strictness::Strict).unwrap_err();
    assert!(matches!(error, JsonError::Dictionary { .. }), "{error}");
    assert_eq!((strict.node_count(), strict.dictionary().attr_type("favourite_colour")), (0, None));

    let mut replica = Replica::new(ReplicaId(1));
    let report = graph.import_into(&mut replica, 1).unwrap();
    assert_eq!(report.warnings.len(), 1, "{:?}", report.warnings);
    let robot = replica.node(NodeId(12)).unwrap();
    assert_eq!(robot.attr("favourite_colour"), Some(&Value::from("red")));
    replica.set_attrs(2, NodeId(12), [("favourite_colour", Value::from("blue"))]).unwrap();
    let refused = replica.set_attrs(3, NodeId(12), [("favourite_food", Value::from("soup"))]).unwrap_err();
    assert!(refused.to_string().contains("unknown attribute name \"favourite_food\""), "{refused}");
    let wrong_type = replica.set_attrs(3, NodeId(12), [("favourite_colour", Value::I32(1))]).unwrap_err();
    assert!(wrong_type.to_string().contains("has type string, not i32"), "{wrong_type}");
}

/// A name met with two types: strictly refused before anything changes (the dictionary included); leniently
/// the second type is kept, with a warning, and local writes of either type are accepted from then on.
#[test]
fn a_name_with_two_types_is_refused_strictly_and_kept_leniently() {
    let mut graph = json::parse_bytes(&fixture("valid_small.json")).unwrap();
    graph.nodes.get_mut(&NodeId(1)).unwrap().attrs.insert("mood".into(), Value::I32(1));
    graph.nodes.get_mut(&NodeId(12)).unwrap().attrs.insert("mood".into(), Value::from("calm"));
    let mut replica = Replica::with_dictionary(ReplicaId(1), Dictionary::permissive());
    let error = graph.import_with(&mut replica, 1, Strictness::Strict).unwrap_err().to_string();
    assert!(
        error.starts_with("DSRModel.symbols[\"12\"].attribute[\"mood\"]: attribute \"mood\" has type i32"),
        "{error}"
    );
    assert_eq!(replica.node_count(), 0);
    assert_eq!(replica.dictionary().attr_type("mood"), None, "the dictionary learnt a name of a refused import");

    let mut replica = Replica::new(ReplicaId(1));
    let report = graph.import_into(&mut replica, 1).unwrap();
    let warnings: Vec<String> = report.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(
        warnings,
        [
            "DSRModel.symbols[\"1\"].attribute[\"mood\"]: unknown attribute name \"mood\" joins this graph's dictionary as i32",
            "DSRModel.symbols[\"12\"].attribute[\"mood\"]: attribute \"mood\" has type string here and i32 in the dictionary: kept as string",
        ]
    );
    assert_eq!(replica.node(NodeId(12)).unwrap().attr("mood"), Some(&Value::from("calm")));
    replica.set_attrs(2, NodeId(1), [("mood", Value::from("glad"))]).unwrap();
    replica.set_attrs(3, NodeId(12), [("mood", Value::I32(3))]).unwrap();
}

#[test]
fn a_refused_import_leaves_the_replica_unchanged() {
    let mut replica = load(&fixture("valid_small.json"), 1).unwrap();
    let digest = replica.digest();
    let clock = replica.clock();
    let log = replica.log_len();

    // A new node and a node whose id the replica already holds.
    let mut clash = CortexGraph::default();
    clash.nodes.insert(NodeId(20), node("transform", "arm", []));
    clash.nodes.insert(NodeId(12), node("omnirobot", "robot_again", []));
    let error = clash.import_into(&mut replica, 5_000).unwrap_err();
    assert_eq!(
        error.to_string(),
        "DSRModel.symbols[\"12\"].id: node id 12 is already in use in the replica or was deleted"
    );
    // A node whose name the replica already holds.
    let mut taken = CortexGraph::default();
    taken.nodes.insert(NodeId(21), node("transform", "robot", []));
    let error = taken.import_into(&mut replica, 5_000).unwrap_err().to_string();
    assert!(error.ends_with("node name \"robot\" is already taken by node 12 of the replica"), "{error}");
    // A link the replica already has.
    let mut again = CortexGraph::default();
    again.edges.insert(EdgeKey::new(NodeId(1), NodeId(12), "RT"), Attributes::new());
    let error = again.import_into(&mut replica, 5_000).unwrap_err().to_string();
    assert!(error.ends_with("edge 1-[RT]->12 already exists in the replica"), "{error}");

    assert_eq!(replica.digest(), digest);
    assert_eq!(replica.clock(), clock);
    assert_eq!(replica.log_len(), log);

    // The same import a second time: every id clashes.
    let graph = json::parse_bytes(&fixture("valid_small.json")).unwrap();
    assert!(matches!(graph.import_into(&mut replica, 5_000), Err(JsonError::IdInUse { .. })));
    assert_eq!(replica.digest(), digest);
}

#[test]
fn a_deleted_id_cannot_be_imported_again() {
    let mut replica = load(&fixture("valid_small.json"), 1).unwrap();
    replica.delete_node(2_000, NodeId(12)).unwrap();
    let mut graph = CortexGraph::default();
    graph.nodes.insert(NodeId(12), node("omnirobot", "robot", []));
    assert!(matches!(graph.import_into(&mut replica, 3_000), Err(JsonError::IdInUse { .. })));
}

#[test]
fn links_may_end_at_nodes_the_replica_already_holds() {
    let mut replica = Replica::new(ReplicaId(1));
    let base = json::parse_bytes(&fixture("valid_small.json")).unwrap().import_into(&mut replica, 1_000).unwrap();
    let mut graph = CortexGraph::default();
    graph.nodes.insert(NodeId(30), node("laser", "laser", [("level", Value::I32(2))]));
    graph.edges.insert(
        EdgeKey::new(NodeId(12), NodeId(30), "RT"),
        Attributes::from([
            ("rt_translation".to_owned(), Value::from(vec![0.0f32, 0.0, 200.0])),
            ("rt_rotation_euler_xyz".to_owned(), Value::from(vec![0.0f32, 0.0, 0.0])),
        ]),
    );
    let report = graph.import_into(&mut replica, 3_000).unwrap();
    assert_eq!((report.nodes, report.edges, report.attributes, report.deltas.len()), (1, 1, 3, 2));
    assert_eq!(replica.transform_point(NodeId(30), NodeId(1), [0.0; 3]).unwrap()[0].round(), 1000.0);
    // The deltas bring another replica to the same state.
    let mut peer = Replica::new(ReplicaId(2));
    for delta in base.deltas.iter().chain(&report.deltas).rev() {
        peer.apply(delta).unwrap();
    }
    assert_eq!(peer.digest(), replica.digest());
}

#[test]
fn a_non_finite_float_cannot_be_exported() {
    let mut graph = CortexGraph::default();
    graph.nodes.insert(NodeId(7), node("world", "world", [("pos_x", Value::F32(f32::NAN))]));
    let error = graph.to_json().unwrap_err();
    assert_eq!(
        error.to_string(),
        "node 7 attribute \"pos_x\": NaN cannot be written as json (only finite numbers can)"
    );
}

#[test]
fn analysis_reports_cycles_several_parents_and_dangling_links_without_hanging() {
    let mut graph = CortexGraph::default();
    for id in 1..=8 {
        graph.nodes.insert(NodeId(id), node("transform", &format!("n{id}"), []));
    }
    let rt = |graph: &mut CortexGraph, from: u64, to: u64| {
        graph.edges.insert(EdgeKey::new(NodeId(from), NodeId(to), "RT"), Attributes::new());
    };
    // Tree 1 → 2 → 3 → 4, and 1 → 5 → 4: node 4 has two parents; the longest path has 3 links.
    rt(&mut graph, 1, 2);
    rt(&mut graph, 2, 3);
    rt(&mut graph, 3, 4);
    rt(&mut graph, 1, 5);
    rt(&mut graph, 5, 4);
    // A cycle 6 → 7 → 6 and a self-link on 8.
    rt(&mut graph, 6, 7);
    rt(&mut graph, 7, 6);
    rt(&mut graph, 8, 8);
    // A dangling link and a non-RT link.
    rt(&mut graph, 3, 99);
    graph.edges.insert(EdgeKey::new(NodeId(1), NodeId(8), "in"), Attributes::new());

    let analysis = graph.analyze();
    assert_eq!(analysis.rt_depth, 3);
    assert_eq!(analysis.rt_roots, vec![NodeId(1)]);
    assert_eq!(analysis.rt_cycles, vec![vec![NodeId(6), NodeId(7)], vec![NodeId(8)]]);
    assert_eq!(analysis.several_rt_parents.len(), 1);
    assert_eq!(analysis.several_rt_parents[0].node, NodeId(4));
    assert_eq!(analysis.several_rt_parents[0].parents, vec![NodeId(3), NodeId(5)]);
    assert_eq!(analysis.dangling_links.len(), 1);
    assert_eq!((analysis.dangling_links[0].dst, analysis.dangling_links[0].missing.clone()), (NodeId(99), vec!["dst"]));
    assert_eq!(analysis.edge_labels, BTreeMap::from([("RT".to_owned(), 9), ("in".to_owned(), 1)]));

    // A long chain closed into one big cycle: found, and nothing recurses deeply.
    let mut ring = CortexGraph::default();
    for id in 1..=100_000u64 {
        ring.nodes.insert(NodeId(id), node("transform", &format!("r{id}"), []));
        rt(&mut ring, id, id % 100_000 + 1);
    }
    let analysis = ring.analyze();
    assert_eq!(analysis.rt_cycles.len(), 1);
    assert_eq!(analysis.rt_cycles[0].len(), 100_000);
    assert_eq!(analysis.rt_depth, 0);
}

#[test]
fn analysis_serializes_ids_as_decimal_strings() {
    let graph = json::parse_bytes(&dataset("giraff_dsr.json")).unwrap();
    let analysis = graph.analyze();
    let text = serde_json::to_string(&analysis).unwrap();
    assert!(text.contains(&format!("\"rt_roots\":[\"{}\"]", analysis.rt_roots[0])), "{text}");
    assert!(text.contains("\"value_type\":\"f32\""));
}

fn node<const N: usize>(node_type: &str, name: &str, attrs: [(&str, Value); N]) -> CortexNode {
    CortexNode {
        node_type: node_type.to_owned(),
        name: name.to_owned(),
        attrs: attrs.into_iter().map(|(name, value)| (name.to_owned(), value)).collect(),
    }
}

fn finite_f32() -> impl Strategy<Value = f32> {
    any::<u32>().prop_map(f32::from_bits).prop_filter("finite", |value| value.is_finite())
}

fn finite_f64() -> impl Strategy<Value = f64> {
    any::<u64>().prop_map(f64::from_bits).prop_filter("finite", |value| value.is_finite())
}

/// Any value of any of the 14 types, floats over all finite bit patterns.
fn any_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        ".{0,12}".prop_map(|text: String| Value::from(text.as_str())),
        any::<i32>().prop_map(Value::I32),
        finite_f32().prop_map(Value::F32),
        prop::collection::vec(finite_f32(), 0..6).prop_map(Value::from),
        any::<bool>().prop_map(Value::Bool),
        prop::collection::vec(any::<u8>(), 0..6).prop_map(|bytes| Value::Bytes(bytes.into())),
        any::<u32>().prop_map(Value::U32),
        any::<u64>().prop_map(Value::U64),
        finite_f64().prop_map(Value::F64),
        prop::collection::vec(any::<u64>(), 0..6).prop_map(Value::from),
        prop::array::uniform2(finite_f32()).prop_map(Value::F32x2),
        prop::array::uniform3(finite_f32()).prop_map(Value::F32x3),
        prop::array::uniform4(finite_f32()).prop_map(Value::F32x4),
        prop::array::uniform6(finite_f32()).prop_map(Value::F32x6),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Every value of every type, written and read back, keeps its type and bits.
    #[test]
    fn any_value_survives_writing_and_reading(
        values in prop::collection::vec(any_value(), 1..8),
        id in 1u64..,
        name in "[a-z][a-z0-9_ ]{0,20}",
    ) {
        let attrs: Attributes = values.iter().enumerate().map(|(index, value)| (format!("a{index}"), value.clone())).collect();
        let mut graph = CortexGraph::default();
        graph.nodes.insert(NodeId(id), CortexNode { node_type: "world".into(), name, attrs: attrs.clone() });
        graph.edges.insert(EdgeKey::new(NodeId(id), NodeId(id), "RT"), attrs);
        let text = graph.to_json().unwrap();
        let reread = json::parse(&text).unwrap();
        prop_assert_eq!(&reread, &graph);
    }

    /// Damaged versions of a real file never panic: they are refused, or read, imported and written back.
    #[test]
    fn mutated_real_files_never_panic(
        which in 0usize..2,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
        cut_at in prop::option::of(any::<prop::sample::Index>()),
    ) {
        let mut bytes = dataset(["shadow_scene.json", "Robot_viriato.json"][which]);
        for (position, byte) in &edits {
            let index = position.index(bytes.len());
            bytes[index] = *byte;
        }
        if let Some(cut_at) = cut_at {
            bytes.truncate(cut_at.index(bytes.len()));
        }
        if let Ok(graph) = json::parse_bytes(&bytes) {
            let _ = graph.analyze();
            let mut replica = Replica::with_dictionary(ReplicaId(1), Dictionary::permissive());
            if graph.import_into(&mut replica, 1).is_ok() {
                let written = json::export(&replica).unwrap();
                prop_assert_eq!(json::parse(&written).unwrap(), graph);
            } else {
                prop_assert_eq!(replica.node_count(), 0);
            }
        }
    }

    /// Random bytes never panic either.
    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..256)) {
        let _ = json::parse_bytes(&bytes);
    }
}
