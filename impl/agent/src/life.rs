//! The incarnation record: one small file per agent id and graph, where each life writes its incarnation before it
//! writes to the graph, so the next life on this host takes a higher one even when no peer is reachable (see the
//! crate's **Identity**). The file holds the number in decimal and a newline; it is replaced atomically (written
//! beside, synced, renamed), so a crash leaves the old record or the new one, never a torn one.

use std::io::Write;
use std::path::Path;

/// The incarnation recorded in `path`, or `None` when there is no such file.
///
/// # Errors
/// The file cannot be read, or does not hold a number (the message names the file and what it holds).
pub fn recorded(path: &Path) -> Result<Option<u32>, String> {
    match std::fs::read_to_string(path) {
        Ok(text) => {
            text.trim().parse::<u32>().map(Some).map_err(|error| {
                format!("{} holds {:?}, not an incarnation number: {error}", path.display(), text.trim())
            })
        }
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(error) => Err(format!("reading {}: {error}", path.display())),
    }
}

/// Records `incarnation` in `path` (creating its directory), durably, unless a higher one is recorded already.
///
/// # Errors
/// The directory or file cannot be written (the message names the path).
pub fn record(path: &Path, incarnation: u32) -> Result<(), String> {
    if recorded(path).ok().flatten().is_some_and(|current| current >= incarnation) {
        return Ok(());
    }
    let context = |what: &str, error: std::io::Error| format!("{what} {}: {error}", path.display());
    if let Some(dir) = path.parent().filter(|dir| !dir.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| context("creating the directory of", e))?;
    }
    let temporary = path.with_extension(format!("tmp{}", std::process::id()));
    let mut file = std::fs::File::create(&temporary).map_err(|e| context("creating a file beside", e))?;
    writeln!(file, "{incarnation}").and_then(|()| file.sync_all()).map_err(|e| context("writing beside", e))?;
    std::fs::rename(&temporary, path).map_err(|e| context("replacing", e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_is_read_back_and_never_lowered() {
        let dir = std::env::temp_dir().join(format!("agent-life-{}", std::process::id()));
        let path = dir.join("nested").join("a1.life");
        assert_eq!(recorded(&path), Ok(None));
        record(&path, 3).unwrap();
        assert_eq!(recorded(&path), Ok(Some(3)));
        record(&path, 2).unwrap();
        assert_eq!(recorded(&path), Ok(Some(3)));
        record(&path, 7).unwrap();
        assert_eq!(recorded(&path), Ok(Some(7)));
        std::fs::write(&path, "seven\n").unwrap();
        assert!(recorded(&path).unwrap_err().contains("not an incarnation number"));
        let _ = std::fs::remove_dir_all(dir);
    }
}
