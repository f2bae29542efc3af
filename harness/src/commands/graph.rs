//! `cortex graph`: look inside CORTEX JSON graphs and convert them through a replica.
//!
//! `info` reads a file without importing it, so it can report what an import would skip (dangling links), the
//! names outside the built-in dictionary, and what would confuse kinematics (RT cycles, several RT parents).
//! `convert` loads the file into a replica and writes the replica back, which normalises a file to this project's
//! canonical output and proves it imports. Both read leniently by default (as the C++ loader does, with a warning
//! for everything converted, skipped or learnt; `dsr::json` states the rules); `--strict` refuses all of that.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::Context as _;
use clap::{Args, Subcommand};
use dsr::json::{self, CortexGraph, GraphAnalysis, JsonWarning, Strictness};
use dsr::{NodeId, Replica, ReplicaId};
use serde::Serialize;

/// Arguments of `cortex graph`.
#[derive(Debug, Args)]
pub struct GraphArgs {
    /// What to do with the graph.
    #[command(subcommand)]
    command: GraphCommand,
}

/// The `cortex graph` subcommands.
#[derive(Debug, Subcommand)]
enum GraphCommand {
    /// Counts by node type, edge label and attribute type, RT depth, dangling links and RT cycles.
    Info {
        /// A CORTEX JSON file.
        file: PathBuf,
        /// Print stable, machine-readable JSON instead of tables.
        #[arg(long)]
        json: bool,
        /// Refuse what the lenient rules accept with a warning.
        #[arg(long)]
        strict: bool,
    },
    /// Load a CORTEX JSON file into a replica and write the replica back as CORTEX JSON.
    Convert {
        /// The file to read.
        input: PathBuf,
        /// The file to write (replaced if it exists).
        output: PathBuf,
        /// Refuse what the lenient rules accept with a warning: unknown names, another type than the dictionary's,
        /// fractions under integer type codes, links with a missing end or listed under another symbol.
        #[arg(long)]
        strict: bool,
    },
}

/// Runs a `cortex graph` subcommand.
///
/// # Errors
/// A file that cannot be read, written or understood, with the file name and the place in it.
pub fn run(args: GraphArgs) -> anyhow::Result<()> {
    match args.command {
        GraphCommand::Info { file, json, strict } => {
            let graph = read_graph(&file, strictness(strict))?;
            let analysis = graph.analyze();
            let text = if json { info_json(&file, &analysis)? } else { info_text(&file, &analysis) };
            print!("{text}");
            Ok(())
        }
        GraphCommand::Convert { input, output, strict } => {
            let graph = read_graph(&input, strictness(strict))?;
            let mut replica = Replica::new(ReplicaId(1));
            let report = graph
                .import_with(&mut replica, now_ns(), strictness(strict))
                .with_context(|| format!("cannot import {}", input.display()))?;
            warn(&input, &report.warnings);
            let text = json::export(&replica).with_context(|| format!("cannot export {}", input.display()))?;
            std::fs::write(&output, text).with_context(|| format!("cannot write {}", output.display()))?;
            println!(
                "wrote {}: {} nodes, {} edges, {} attributes",
                output.display(),
                report.nodes,
                report.edges,
                report.attributes
            );
            Ok(())
        }
    }
}

fn strictness(strict: bool) -> Strictness {
    if strict { Strictness::Strict } else { Strictness::Lenient }
}

/// Reads a file, printing the read's warnings on standard error.
fn read_graph(path: &Path, strictness: Strictness) -> anyhow::Result<CortexGraph> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let reading = json::read(&bytes, strictness).with_context(|| format!("cannot load {}", path.display()))?;
    warn(path, &reading.warnings);
    Ok(reading.graph)
}

fn warn(path: &Path, warnings: &[JsonWarning]) {
    for warning in warnings {
        eprintln!("warning: {}: {warning}", path.display());
    }
}

/// Wall-clock time in ns for the import's operations (they only order the replica's own writes).
fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |elapsed| u64::try_from(elapsed.as_nanos()).unwrap_or(0))
}

/// The `--json` form of `info`: the file name, then the analysis; keys in a fixed order, maps sorted.
#[derive(Serialize)]
struct InfoReport<'a> {
    file: String,
    #[serde(flatten)]
    analysis: &'a GraphAnalysis,
}

fn info_json(file: &Path, analysis: &GraphAnalysis) -> anyhow::Result<String> {
    let report = InfoReport { file: file.display().to_string(), analysis };
    let mut text = serde_json::to_string_pretty(&report).context("cannot write the report as json")?;
    text.push('\n');
    Ok(text)
}

fn ids(ids: &[NodeId]) -> String {
    ids.iter().map(NodeId::to_string).collect::<Vec<_>>().join(", ")
}

fn none_or<T>(items: &[T], show: impl Fn(&T) -> String) -> String {
    if items.is_empty() { "none".to_owned() } else { items.iter().map(show).collect::<Vec<_>>().join("; ") }
}

/// The human-readable form of `info`: a summary, then one table per count.
fn info_text(file: &Path, analysis: &GraphAnalysis) -> String {
    let mut text = String::new();
    let summary = [
        ("file", file.display().to_string()),
        ("nodes", analysis.nodes.to_string()),
        ("edges", analysis.edges.to_string()),
        ("attributes", analysis.attributes.to_string()),
        ("RT root ids", if analysis.rt_roots.is_empty() { "none".to_owned() } else { ids(&analysis.rt_roots) }),
        ("RT depth", analysis.rt_depth.to_string()),
        (
            "dangling links",
            none_or(&analysis.dangling_links, |link| {
                format!("{}-[{}]->{} (missing {})", link.src, link.label, link.dst, link.missing.join(" and "))
            }),
        ),
        ("RT cycles", none_or(&analysis.rt_cycles, |group| format!("through {}", ids(group)))),
        (
            "several RT parents",
            none_or(&analysis.several_rt_parents, |node| format!("{} has {}", node.node, ids(&node.parents))),
        ),
        ("unknown node types", none_or(&analysis.outside_dictionary.node_types, String::clone)),
        ("unknown edge types", none_or(&analysis.outside_dictionary.edge_labels, String::clone)),
        ("unknown attributes", none_or(&analysis.outside_dictionary.attributes, String::clone)),
        ("retyped attributes", none_or(&analysis.outside_dictionary.other_types, String::clone)),
    ];
    let width = summary.iter().map(|(label, _)| label.len()).max().unwrap_or(0);
    for (label, value) in summary {
        let _ = writeln!(text, "{label:<width$}  {value}");
    }
    let counts = |map: &std::collections::BTreeMap<String, usize>| -> Vec<Vec<String>> {
        map.iter().map(|(name, count)| vec![name.clone(), count.to_string()]).collect()
    };
    text.push('\n');
    text.push_str(&table(&["node type", "count"], &counts(&analysis.node_types)));
    text.push('\n');
    text.push_str(&table(&["edge label", "count"], &counts(&analysis.edge_labels)));
    text.push('\n');
    let by_type: Vec<Vec<String>> = analysis
        .attribute_types
        .iter()
        .map(|count| vec![count.value_type.to_string(), count.code.to_string(), count.count.to_string()])
        .collect();
    text.push_str(&table(&["attribute type", "code", "count"], &by_type));
    text.push('\n');
    let by_name: Vec<Vec<String>> = analysis
        .attribute_names
        .iter()
        .map(|count| {
            vec![
                count.name.clone(),
                count.value_type.to_string(),
                count.on_nodes.to_string(),
                count.on_edges.to_string(),
            ]
        })
        .collect();
    text.push_str(&table(&["attribute", "type", "on nodes", "on edges"], &by_name));
    text
}

/// A plain-text table: the first two columns left-aligned, numbers right-aligned; a rule under the header.
fn table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut widths: Vec<usize> = header.iter().map(|title| title.chars().count()).collect();
    for row in rows {
        for (width, cell) in widths.iter_mut().zip(row) {
            *width = (*width).max(cell.chars().count());
        }
    }
    let numeric = |column: usize| column > 0 && rows.iter().all(|row| row[column].parse::<u64>().is_ok());
    let mut text = String::new();
    let mut line = |cells: &mut dyn Iterator<Item = String>| {
        let mut out = String::new();
        for (column, cell) in cells.enumerate() {
            if column > 0 {
                out.push_str("  ");
            }
            let width = widths[column];
            if numeric(column) {
                let _ = write!(out, "{cell:>width$}");
            } else {
                let _ = write!(out, "{cell:<width$}");
            }
        }
        text.push_str(out.trim_end());
        text.push('\n');
    };
    line(&mut header.iter().map(|title| (*title).to_owned()));
    line(&mut widths.iter().map(|width| "-".repeat(*width)));
    for row in rows {
        line(&mut row.iter().cloned());
    }
    text
}
