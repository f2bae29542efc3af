//! The incarnation record: one small file per agent id and graph, where each life writes its incarnation before it
//! writes to the graph, so the next life on this host takes a higher one even when no peer is reachable (see the
//! crate's **Identity**). The file holds the number in decimal and a newline, then the id of the graph that life
//! belonged to (`graph <16 hex digits>`, followed by ` unnamed` when the graph is unnamed, see `agent::core`,
//! **Graphs**; files written before graph ids have no such line), so a restarted agent that names no graph rejoins
//! its own rather than creating a new one. It is replaced atomically (written beside,
//! synced, renamed), so a crash leaves the old record or the new one, never a torn one.

use std::io::Write;
use std::path::Path;

use crate::graph_id::GraphId;

/// The incarnation recorded in `path`, or `None` when there is no such file.
///
/// # Errors
/// The file cannot be read, or does not hold a number (the message names the file and what it holds).
pub fn recorded(path: &Path) -> Result<Option<u32>, String> {
    Ok(read(path)?.map(|(incarnation, _)| incarnation))
}

/// The graph recorded in `path` by the previous life, and whether it is named; `None` when there is no file or
/// it names no graph.
///
/// # Errors
/// As [`recorded`], or a graph line that is not a graph id.
pub fn recorded_graph(path: &Path) -> Result<Option<(GraphId, bool)>, String> {
    Ok(read(path)?.and_then(|(_, graph)| graph))
}

/// A record: the incarnation, and the graph with whether it is named.
type Record = (u32, Option<(GraphId, bool)>);

fn read(path: &Path) -> Result<Option<Record>, String> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(error) => return Err(format!("reading {}: {error}", path.display())),
    };
    let mut lines = text.lines().map(str::trim).filter(|line| !line.is_empty());
    let first = lines.next().unwrap_or_default();
    let incarnation = first
        .parse::<u32>()
        .map_err(|error| format!("{} holds {first:?}, not an incarnation number: {error}", path.display()))?;
    let graph = match lines.next() {
        None => None,
        Some(line) => {
            let not_graph =
                || format!("{}: second line {line:?} is not `graph <16 hex digits>[ unnamed]`", path.display());
            let id = line.strip_prefix("graph ").ok_or_else(not_graph)?;
            let (id, named) = match id.strip_suffix(" unnamed") {
                Some(id) => (id, false),
                None => (id, true),
            };
            Some((id.parse::<GraphId>().map_err(|error| format!("{}: {error}", path.display()))?, named))
        }
    };
    Ok(Some((incarnation, graph)))
}

/// Records `incarnation` and `graph` in `path` (creating its directory), durably; the incarnation recorded is
/// never lowered. `named` says whether the graph is named (`agent::core`, **Graphs**): the next life names a named
/// graph, and starts alone in an unnamed one only if it hears no graph.
///
/// # Errors
/// The directory or file cannot be written (the message names the path).
pub fn record(path: &Path, incarnation: u32, graph: GraphId, named: bool) -> Result<(), String> {
    let current = read(path).ok().flatten();
    if current.is_some_and(|(at, recorded)| at >= incarnation && recorded == Some((graph, named))) {
        return Ok(());
    }
    let incarnation = incarnation.max(current.map_or(0, |(at, _)| at));
    let context = |what: &str, error: std::io::Error| format!("{what} {}: {error}", path.display());
    if let Some(dir) = path.parent().filter(|dir| !dir.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| context("creating the directory of", e))?;
    }
    let temporary = path.with_extension(format!("tmp{}", std::process::id()));
    let mut file = std::fs::File::create(&temporary).map_err(|e| context("creating a file beside", e))?;
    let unnamed = if named { "" } else { " unnamed" };
    writeln!(file, "{incarnation}\ngraph {graph}{unnamed}")
        .and_then(|()| file.sync_all())
        .map_err(|e| context("writing beside", e))?;
    std::fs::rename(&temporary, path).map_err(|e| context("replacing", e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_is_read_back_and_never_lowered() {
        let dir = std::env::temp_dir().join(format!("agent-life-{}", std::process::id()));
        let path = dir.join("nested").join("a1.life");
        let graph = GraphId::from_nonce(1);
        assert_eq!(recorded(&path), Ok(None));
        record(&path, 3, graph, true).unwrap();
        assert_eq!(recorded(&path), Ok(Some(3)));
        assert_eq!(recorded_graph(&path), Ok(Some((graph, true))));
        record(&path, 2, graph, true).unwrap();
        assert_eq!(recorded(&path), Ok(Some(3)));
        record(&path, 7, graph, true).unwrap();
        assert_eq!(recorded(&path), Ok(Some(7)));
        record(&path, 8, graph, false).unwrap();
        assert_eq!((recorded(&path), recorded_graph(&path)), (Ok(Some(8)), Ok(Some((graph, false)))));
        std::fs::write(&path, "4\n").unwrap();
        assert_eq!((recorded(&path), recorded_graph(&path)), (Ok(Some(4)), Ok(None)));
        std::fs::write(&path, "seven\n").unwrap();
        assert!(recorded(&path).unwrap_err().contains("not an incarnation number"));
        let _ = std::fs::remove_dir_all(dir);
    }
}
