//! `cortex graph` as a user runs it: the built binary on a real CORTEX graph and on broken files, checking what
//! it prints and its exit code.

use std::path::PathBuf;
use std::process::{Command, Output};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn real_graph(name: &str) -> PathBuf {
    workspace().join("datasets/cortex-graphs").join(name)
}

fn fixture(name: &str) -> PathBuf {
    workspace().join("impl/dsr/tests/fixtures/json").join(name)
}

fn cortex(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cortex")).args(args).output().expect("cortex runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8(bytes.to_vec()).expect("utf-8 output")
}

#[test]
fn info_prints_counts_depth_and_structure_of_a_real_graph() {
    let path = real_graph("autonomyLab_complete.json");
    let output = cortex(&["graph".as_ref(), "info".as_ref(), path.as_os_str()]);
    assert!(output.status.success(), "stderr: {}", text(&output.stderr));
    let stdout = text(&output.stdout);
    for line in [
        "nodes               81",
        "edges               80",
        "RT depth            6",
        "dangling links      none",
        "RT cycles           none",
        "several RT parents  none",
        "plane         31",
        "RT             80",
        "u64                7     81",
        "rt_translation                     vec<f32>         0        80",
    ] {
        assert!(stdout.contains(line), "missing {line:?} in:\n{stdout}");
    }
}

#[test]
fn info_json_is_stable_and_machine_readable() {
    let path = real_graph("giraff_dsr.json");
    let run = || cortex(&["graph".as_ref(), "info".as_ref(), path.as_os_str(), "--json".as_ref()]);
    let (first, second) = (run(), run());
    assert!(first.status.success(), "stderr: {}", text(&first.stderr));
    assert_eq!(first.stdout, second.stdout);
    let report: serde_json::Value = serde_json::from_slice(&first.stdout).expect("json output");
    assert_eq!(report["nodes"], 62);
    assert_eq!(report["edges"], 61);
    assert_eq!(report["edge_labels"]["has"], 2);
    assert_eq!(report["rt_cycles"], serde_json::json!([]));
    assert!(report["rt_roots"][0].is_string(), "ids are decimal strings: {report}");
}

#[test]
fn info_reports_dangling_links_of_a_file_an_import_would_refuse() {
    let path = fixture("dangling_dst.json");
    let output = cortex(&["graph".as_ref(), "info".as_ref(), path.as_os_str()]);
    assert!(output.status.success(), "stderr: {}", text(&output.stderr));
    assert!(text(&output.stdout).contains("dangling links      1-[RT]->99 (missing dst)"));
}

#[test]
fn a_malformed_file_fails_with_one_line_naming_file_and_place() {
    let path = fixture("int32_out_of_range.json");
    let output = cortex(&["graph".as_ref(), "info".as_ref(), path.as_os_str()]);
    assert_eq!(output.status.code(), Some(1));
    assert!(output.stdout.is_empty());
    let stderr = text(&output.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.starts_with("error: cannot load "), "{stderr}");
    assert!(stderr.contains("int32_out_of_range.json"), "{stderr}");
    assert!(
        stderr.contains(
            "DSRModel.symbols[\"12\"].attribute[\"level\"].value: the number 3000000000 is out of the i32 range"
        ),
        "{stderr}"
    );
}

#[test]
fn convert_round_trips_a_real_graph_and_refuses_a_bad_one() {
    let scratch = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let first = scratch.join("viriato_once.json");
    let second = scratch.join("viriato_twice.json");
    let input = real_graph("Robot_viriato.json");
    let output = cortex(&["graph".as_ref(), "convert".as_ref(), input.as_os_str(), first.as_os_str()]);
    assert!(output.status.success(), "stderr: {}", text(&output.stderr));
    assert!(text(&output.stdout).contains("14 nodes, 13 edges"));
    let output = cortex(&["graph".as_ref(), "convert".as_ref(), first.as_os_str(), second.as_os_str()]);
    assert!(output.status.success(), "stderr: {}", text(&output.stderr));
    let once = std::fs::read(&first).unwrap();
    assert_eq!(once, std::fs::read(&second).unwrap(), "converting the output again changes it");
    assert_eq!(
        dsr::json::parse_bytes(&once).unwrap(),
        dsr::json::parse_bytes(&std::fs::read(&input).unwrap()).unwrap(),
        "the converted graph differs from the original"
    );

    let bad = fixture("dangling_dst.json");
    let target = scratch.join("never_written.json");
    let _ = std::fs::remove_file(&target);
    let output =
        cortex(&["graph".as_ref(), "convert".as_ref(), "--strict".as_ref(), bad.as_os_str(), target.as_os_str()]);
    assert_eq!(output.status.code(), Some(1));
    let stderr = text(&output.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("cannot import") && stderr.contains("node 99 does not exist"), "{stderr}");
    assert!(!target.exists(), "a refused conversion wrote its output");
}

/// Unknown names are accepted by default, with a warning naming the place, and `info` lists them; `--strict`
/// refuses them.
#[test]
fn convert_accepts_unknown_names_unless_strict() {
    let scratch = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let input = fixture("unknown_attribute.json");
    let target = scratch.join("unknown_attribute_out.json");
    let _ = std::fs::remove_file(&target);
    let strict =
        cortex(&["graph".as_ref(), "convert".as_ref(), "--strict".as_ref(), input.as_os_str(), target.as_os_str()]);
    assert_eq!(strict.status.code(), Some(1));
    assert!(text(&strict.stderr).contains("unknown attribute name \"favourite_colour\""));
    assert!(!target.exists(), "a refused conversion wrote its output");
    let lenient = cortex(&["graph".as_ref(), "convert".as_ref(), input.as_os_str(), target.as_os_str()]);
    assert!(lenient.status.success(), "stderr: {}", text(&lenient.stderr));
    let warning = "warning: ";
    let stderr = text(&lenient.stderr);
    assert!(stderr.starts_with(warning) && stderr.contains("attribute[\"favourite_colour\"]: unknown"), "{stderr}");
    assert!(text(&std::fs::read(&target).unwrap()).contains("\"favourite_colour\""));
    let info = cortex(&["graph".as_ref(), "info".as_ref(), input.as_os_str()]);
    assert!(
        text(&info.stdout)
            .lines()
            .any(|line| line.starts_with("unknown attributes") && line.ends_with("favourite_colour"))
    );
}

/// A real graph whose `parent` is a u32 (type code 6, an older CORTEX) keeps it, and `info` says so.
#[test]
fn info_lists_names_stored_with_another_type_than_the_dictionarys() {
    let input = workspace().join("datasets/cortex-graphs/furniture.json");
    let output = cortex(&["graph".as_ref(), "info".as_ref(), "--json".as_ref(), input.as_os_str()]);
    assert!(output.status.success(), "stderr: {}", text(&output.stderr));
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let other_types = &report["outside_dictionary"]["other_types"];
    assert_eq!(other_types, &serde_json::json!(["parent: u32 (dictionary: u64)"]), "{report}");
}

#[test]
fn a_missing_file_and_a_bad_command_line_fail_clearly() {
    let missing = workspace().join("no/such/graph.json");
    let output = cortex(&["graph".as_ref(), "info".as_ref(), missing.as_os_str()]);
    assert_eq!(output.status.code(), Some(1));
    assert!(text(&output.stderr).starts_with("error: cannot read "), "{}", text(&output.stderr));
    let output = cortex(&["graph".as_ref(), "frobnicate".as_ref()]);
    assert_eq!(output.status.code(), Some(2));
}
