//! The typed lines exchanged between `cortex chaos` and its agent processes (`cortex chaos-agent`): commands on the
//! agent's standard input, reports on its standard output, one JSON object per line.
//!
//! A write is recorded with everything the reference specification (`model::spec`) needs to say what the graph
//! must be: the dots the operation generated, its hybrid-logical-clock stamp, the operations its replica had
//! applied when it was made (`Replica::applied`, the same set anti-entropy exchanges) and what it did. Large values
//! (a camera frame) are recorded as the seed that generates their bytes ([`RecordedValue::Pattern`]), so the history
//! stays small and still says exactly which bytes were written.

use agent::StatusLine;
use dsr::{CausalContext, Element, NodeId, Value};
use serde::{Deserialize, Serialize};

/// A command to a chaos agent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Command {
    /// Make one operation, chosen by `draw` and the agent's graph; answered by [`Report::Wrote`] or
    /// [`Report::Skipped`].
    Write {
        /// The campaign's number of this write.
        seq: u64,
        /// The random draw that chooses the operation and its values.
        draw: u64,
    },
    /// Report the final state ([`Report::Final`]).
    Final,
}

/// A line a chaos agent prints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Report {
    /// Its status, every `--status-ms`.
    Status(StatusLine),
    /// A write it made.
    Wrote(WriteRecord),
    /// A write it could not make (not joined yet, nothing to operate on, an id collision): no operation happened.
    Skipped {
        /// The campaign's number of the write.
        seq: u64,
        /// Why.
        reason: String,
    },
    /// Its final state.
    Final(FinalState),
}

/// An agent's final state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FinalState {
    /// The graph it is in (`None`: no graph, or a state taken from a replica alone, as the checks' tests do).
    #[serde(default)]
    pub graph: Option<agent::GraphId>,
    /// The digest of its visible graph (the first 8 bytes, hex).
    pub digest: Option<String>,
    /// The full digest (32 bytes, hex), compared with the specification's.
    pub full_digest: Option<String>,
    /// The operations it has applied.
    pub applied: Option<CausalContext>,
    /// Visible nodes.
    pub nodes: usize,
    /// Visible edges.
    pub edges: usize,
}

/// One write as the campaign records it in `history.jsonl`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WriteRecord {
    /// The campaign's number of the write.
    pub seq: u64,
    /// The agent (its `--id`).
    pub agent: u32,
    /// The replica id of the agent's life that made it.
    pub replica: u32,
    /// First dot counter it generated (the operation's id is `(replica, first)`).
    pub first: u64,
    /// Last dot counter it generated.
    pub last: u64,
    /// Its hybrid-logical-clock stamp (the replica's clock right after it).
    pub stamp: u64,
    /// The operations the replica had applied when it made this one.
    pub past: CausalContext,
    /// What it did.
    pub op: RecordedOp,
    /// Milliseconds since the campaign started when the campaign received this record (filled by the campaign).
    #[serde(default)]
    pub at_ms: f64,
}

/// A value as recorded: itself, or the pattern that generates a large byte value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordedValue {
    /// The value itself.
    Plain(Value),
    /// `len` bytes generated from `seed` by [`crate::commands::chaos::workload::pattern`].
    Pattern {
        /// The generator's seed.
        seed: u64,
        /// Number of bytes.
        len: usize,
    },
}

/// What a recorded write did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RecordedOp {
    /// Inserted a node.
    InsertNode {
        /// The node.
        id: NodeId,
        /// Its type.
        node_type: String,
        /// Its name.
        name: String,
        /// Its initial attributes.
        attrs: Vec<(String, RecordedValue)>,
    },
    /// Deleted a node.
    DeleteNode {
        /// The node.
        id: NodeId,
    },
    /// Inserted an edge.
    InsertEdge {
        /// Source node.
        from: NodeId,
        /// Destination node.
        to: NodeId,
        /// Edge type.
        edge_type: String,
    },
    /// Deleted an edge.
    DeleteEdge {
        /// Source node.
        from: NodeId,
        /// Destination node.
        to: NodeId,
        /// Edge type.
        edge_type: String,
    },
    /// Wrote an attribute.
    SetAttr {
        /// The element.
        element: Element,
        /// The attribute.
        name: String,
        /// The value.
        value: RecordedValue,
    },
    /// Removed an attribute.
    RemoveAttr {
        /// The element.
        element: Element,
        /// The attribute.
        name: String,
    },
}

impl RecordedOp {
    /// A short name of the kind of operation, for counts.
    pub fn kind(&self) -> &'static str {
        match self {
            RecordedOp::InsertNode { .. } => "insert_node",
            RecordedOp::DeleteNode { .. } => "delete_node",
            RecordedOp::InsertEdge { .. } => "insert_edge",
            RecordedOp::DeleteEdge { .. } => "delete_edge",
            RecordedOp::SetAttr { value: RecordedValue::Pattern { .. }, .. } => "set_image",
            RecordedOp::SetAttr { .. } => "set_attr",
            RecordedOp::RemoveAttr { .. } => "remove_attr",
        }
    }
}

/// Parses one line of a chaos agent's output.
///
/// # Errors
/// The line is not a [`Report`]; the message quotes its start.
pub fn parse_report(line: &str) -> Result<Report, String> {
    serde_json::from_str(line).map_err(|e| format!("not a chaos agent report ({e}): {:?}", prefix(line)))
}

/// Parses one command line.
///
/// # Errors
/// The line is not a [`Command`]; the message quotes its start.
pub fn parse_command(line: &str) -> Result<Command, String> {
    serde_json::from_str(line).map_err(|e| format!("not a chaos command ({e}): {:?}", prefix(line)))
}

fn prefix(line: &str) -> String {
    line.chars().take(80).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_and_reports_round_trip_and_garbage_is_refused_with_the_line() {
        let command = Command::Write { seq: 3, draw: 99 };
        assert_eq!(parse_command(&serde_json::to_string(&command).unwrap()), Ok(command));
        assert_eq!(parse_command("\"final\""), Ok(Command::Final));
        let record = WriteRecord {
            seq: 1,
            agent: 2,
            replica: 77,
            first: 4,
            last: 5,
            stamp: 123,
            past: CausalContext::from_dots([dsr::Dot::new(dsr::ReplicaId(9), 1)]),
            op: RecordedOp::SetAttr {
                element: Element::Node(NodeId(5)),
                name: "pos_x".into(),
                value: RecordedValue::Plain(Value::F32(0.1)),
            },
            at_ms: 0.0,
        };
        let line = serde_json::to_string(&Report::Wrote(record.clone())).unwrap();
        assert_eq!(parse_report(&line), Ok(Report::Wrote(record)));
        let error = parse_report("{\"wrote\": 3}").unwrap_err();
        assert!(error.contains("not a chaos agent report") && error.contains("wrote"), "{error}");
    }
}
