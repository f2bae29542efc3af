//! rosbag2 bags: a directory with a `metadata.yaml` naming its storage (`sqlite3`, the default up to ROS 2 Humble,
//! or `mcap`) and its storage files (`relative_file_paths`). Each file is read into the same `Contents` as an MCAP
//! file's, and the files' messages are joined (sorted by log time by [`crate::log`]).
//!
//! SQLite storage is read through `rusqlite` (SQLite built from source, so nothing is needed on the machine): the
//! `topics` table gives the channels (the topic, its type and serialization format), the `message_definitions` table,
//! when the file has one (rosbag2 from ROS 2 Iron on), the schemas' definitions, and the `messages` table the messages
//! (`timestamp` is the log time; each payload is copied out of SQLite once). A file that SQLite cannot read, or a
//! table that is missing or malformed, is damage naming the table and the row; with recovery the rows read before it
//! are kept. MCAP storage files are plain ROS 2 MCAP files ([`crate::mcap`]).
//!
//! Only the two keys of `metadata.yaml` that say where the messages are, `storage_identifier` and
//! `relative_file_paths`, are read (with `compression_format`, to refuse per-file compressed bags clearly); the rest
//! (counts, durations, QoS) repeats what the storage holds.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use bytes::Bytes;
use rusqlite::{Connection, OpenFlags};

use crate::contents::{
    Channel, Container, Contents, Damage, DamageKind, LogError, Message, Place, ReadOptions, Schema, map_file,
};

/// What `metadata.yaml` says about where the messages are.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Metadata {
    /// `storage_identifier`: `sqlite3` or `mcap`.
    pub storage: String,
    /// `relative_file_paths`, in order.
    pub files: Vec<String>,
    /// `compression_format` (empty for none).
    pub compression: String,
}

impl Metadata {
    /// Reads the keys this reader needs from the text of a `metadata.yaml` (block-style YAML as rosbag2 writes it).
    pub fn parse(text: &str) -> Metadata {
        let mut metadata = Metadata::default();
        let mut in_files = false;
        for line in text.lines() {
            let trimmed = line.trim();
            if in_files {
                match trimmed.strip_prefix("- ") {
                    Some(file) => metadata.files.push(unquote(file).to_owned()),
                    None => in_files = false,
                }
            }
            if let Some(value) = trimmed.strip_prefix("storage_identifier:") {
                metadata.storage = unquote(value.trim()).to_owned();
            } else if let Some(value) = trimmed.strip_prefix("compression_format:") {
                metadata.compression = unquote(value.trim()).to_owned();
            } else if trimmed.starts_with("relative_file_paths:") {
                in_files = true;
            }
        }
        metadata
    }
}

fn unquote(value: &str) -> &str {
    value.trim_matches(|c| c == '\'' || c == '"')
}

/// Reads a rosbag2 directory: its container and what its storage files hold.
///
/// # Errors
/// [`LogError::Damaged`] on damage (a missing or unusable `metadata.yaml`, a storage file that cannot be read)
/// unless `options.recover`; [`LogError::Open`] if a storage file cannot be opened.
pub(crate) fn read_dir(dir: &Path, options: ReadOptions) -> Result<(Container, Contents), LogError> {
    let metadata_path = dir.join("metadata.yaml");
    let metadata = std::fs::read_to_string(&metadata_path).map(|text| Metadata::parse(&text));
    let metadata_damage = |what: String| LogError::Damaged {
        file: metadata_path.display().to_string(),
        damage: Box::new(Place::file(0).damage("metadata.yaml", DamageKind::Metadata(what))),
    };
    let metadata = match metadata {
        Ok(metadata) => metadata,
        Err(error) => return Err(metadata_damage(format!("a rosbag2 directory needs its metadata.yaml: {error}"))),
    };
    let container = match metadata.storage.as_str() {
        "sqlite3" => Container::Rosbag2Sqlite3,
        "mcap" => Container::Rosbag2Mcap,
        other => return Err(metadata_damage(format!("storage_identifier `{other}`: only sqlite3 and mcap are read"))),
    };
    if !metadata.compression.is_empty() {
        let what = format!("compression_format `{}`: per-file compressed bags are not read", metadata.compression);
        return Err(metadata_damage(what));
    }
    if metadata.files.is_empty() {
        return Err(metadata_damage("relative_file_paths lists no storage file".to_owned()));
    }
    let mut joined = Contents { profile: "ros2".to_owned(), ..Contents::default() };
    for file in &metadata.files {
        let path: PathBuf = dir.join(file);
        let member = path.display().to_string();
        let contents = match container {
            Container::Rosbag2Sqlite3 => read_sqlite(&path, &member, options)?,
            _ => read_mcap(&path, &member, options)?,
        };
        let stop = contents.failure.is_some();
        join(&mut joined, contents);
        if stop {
            break;
        }
    }
    Ok((container, joined))
}

/// Adds one storage file's contents to the bag's: channels by topic (new topics get the next free ids), messages,
/// sizes, and the damage (with its resume point counted from the bag's first byte).
fn join(joined: &mut Contents, contents: Contents) {
    let before = joined.input_bytes;
    for channel in contents.channels.into_values() {
        if !joined.channels.values().any(|known| known.topic == channel.topic) {
            let id = joined.channels.len() as u16;
            if let Some(schema) = &channel.schema {
                joined.schemas.insert(id + 1, schema.clone());
            }
            joined.channels.insert(id, channel);
        }
    }
    joined.messages.extend(contents.messages);
    joined.input_bytes += contents.input_bytes;
    joined.failure = contents.failure.map(|(damage, resume)| (damage, before + resume));
}

fn read_mcap(path: &Path, name: &str, options: ReadOptions) -> Result<Contents, LogError> {
    let open_error = |source| LogError::Open { path: name.to_owned(), source };
    let file = std::fs::File::open(path).map_err(open_error)?;
    let bytes = map_file(&file).map_err(open_error)?;
    crate::mcap::read(&bytes, options).check(name, options)
}

/// Damage in an SQLite table: `row` is the row id (0 for the table as a whole).
fn table_damage(table: &'static str, record: &'static str, row: i64, what: impl ToString) -> Damage {
    let offset = u64::try_from(row).unwrap_or(0);
    Damage { offset, chunk: None, record, table: Some(table), kind: DamageKind::Sqlite(what.to_string()) }
}

/// Reads one rosbag2 SQLite storage file.
///
/// # Errors
/// [`LogError::Damaged`] if SQLite cannot read it (or a table) and `options.recover` is off; with it, the rows read
/// before the damage are kept.
pub(crate) fn read_sqlite(path: &Path, name: &str, options: ReadOptions) -> Result<Contents, LogError> {
    let input_bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let mut contents = Contents { profile: "ros2".to_owned(), input_bytes, ..Contents::default() };
    if let Err(damage) = read_tables(path, &mut contents) {
        let read: u64 = contents.messages.iter().map(|m| m.data.len() as u64).sum();
        contents.failure = Some((damage, read.min(input_bytes)));
    }
    contents.check(name, options)
}

fn read_tables(path: &Path, contents: &mut Contents) -> Result<(), Damage> {
    let flags = OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX;
    let db = Connection::open_with_flags(path, flags).map_err(|e| table_damage("sqlite_master", "file", 0, e))?;
    let definitions = read_definitions(&db)?;
    let by_topic_id = read_topics(&db, &definitions, contents)?;
    read_messages(&db, &by_topic_id, contents)
}

/// The `message_definitions` table (absent before ROS 2 Iron): type name → (encoding, definition text).
fn read_definitions(db: &Connection) -> Result<BTreeMap<String, (String, String)>, Damage> {
    let fail = |e: rusqlite::Error| table_damage("message_definitions", "message definition", 0, e);
    let exists: bool = db
        .query_row(
            "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'message_definitions'",
            [],
            |row| row.get::<_, i64>(0),
        )
        .map(|count| count > 0)
        .map_err(|e| table_damage("sqlite_master", "table", 0, e))?;
    let mut definitions = BTreeMap::new();
    if !exists {
        return Ok(definitions);
    }
    let mut statement =
        db.prepare("SELECT topic_type, encoding, encoded_message_definition FROM message_definitions").map_err(fail)?;
    let rows = statement.query_map([], |row| Ok((row.get(0)?, row.get(1)?, row.get(2)?))).map_err(fail)?;
    for row in rows {
        let (type_name, encoding, text): (String, String, String) = row.map_err(fail)?;
        definitions.insert(type_name, (encoding, text));
    }
    Ok(definitions)
}

/// The `topics` table as channels (ids in row order); returns the channel of each topic id.
fn read_topics(
    db: &Connection,
    definitions: &BTreeMap<String, (String, String)>,
    contents: &mut Contents,
) -> Result<BTreeMap<i64, Arc<Channel>>, Damage> {
    let fail = |row: i64| move |e: rusqlite::Error| table_damage("topics", "topic", row, e);
    let mut statement =
        db.prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id").map_err(fail(0))?;
    let rows =
        statement.query_map([], |row| Ok((row.get(0)?, row.get(1)?, row.get(2)?, row.get(3)?))).map_err(fail(0))?;
    let mut by_topic_id = BTreeMap::new();
    for row in rows {
        let (topic_id, topic, type_name, format): (i64, String, String, String) = row.map_err(fail(0))?;
        let Ok(id) = u16::try_from(by_topic_id.len()) else {
            let kind = DamageKind::BadField { field: "id", what: "more than 65,535 topics".to_owned() };
            return Err(Damage { kind, ..table_damage("topics", "topic", topic_id, "") });
        };
        let (encoding, text) = definitions.get(&type_name).cloned().unwrap_or_default();
        let schema = Arc::new(Schema { id: id + 1, name: type_name, encoding, data: Bytes::from(text) });
        let channel = Arc::new(Channel {
            id,
            topic,
            message_encoding: format,
            schema: Some(schema.clone()),
            metadata: BTreeMap::new(),
        });
        contents.schemas.insert(id + 1, schema);
        contents.channels.insert(id, channel.clone());
        by_topic_id.insert(topic_id, channel);
    }
    Ok(by_topic_id)
}

/// The `messages` table, row by row; each payload is copied once out of SQLite.
fn read_messages(
    db: &Connection,
    by_topic_id: &BTreeMap<i64, Arc<Channel>>,
    contents: &mut Contents,
) -> Result<(), Damage> {
    let fail = |row: i64| move |e: rusqlite::Error| table_damage("messages", "message", row, e);
    let mut statement =
        db.prepare("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id").map_err(fail(0))?;
    let mut rows = statement.query([]).map_err(fail(0))?;
    let mut last_row = 0;
    let mut sequence = 0u32;
    while let Some(row) = rows.next().map_err(|e| fail(last_row + 1)(e))? {
        let row_id: i64 = row.get(0).map_err(fail(last_row + 1))?;
        last_row = row_id;
        let topic_id: i64 = row.get(1).map_err(fail(row_id))?;
        let timestamp: i64 = row.get(2).map_err(fail(row_id))?;
        let data: &[u8] = row.get_ref(3).and_then(|value| Ok(value.as_blob()?)).map_err(fail(row_id))?;
        let channel = by_topic_id.get(&topic_id).cloned().ok_or_else(|| Damage {
            kind: DamageKind::BadField { field: "topic_id", what: format!("no topic has id {topic_id}") },
            ..table_damage("messages", "message", row_id, "")
        })?;
        let log_time = u64::try_from(timestamp).unwrap_or(0);
        contents.messages.push(Message {
            channel,
            sequence,
            log_time,
            publish_time: log_time,
            data: Bytes::copy_from_slice(data),
            file_offset: u64::try_from(row_id).unwrap_or(0),
        });
        sequence = sequence.wrapping_add(1);
    }
    Ok(())
}
