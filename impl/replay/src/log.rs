//! Reading robot logs: whatever the container, a log becomes the same [`Log`] — schemas (a message type, its
//! definition's encoding and text), channels (a topic, its message encoding, its schema) and messages in log-time
//! order, each payload a [`Bytes`] view that borrows from the memory-mapped file or a decompressed chunk, so a camera
//! frame is never copied on the way in.
//!
//! The container is detected from the content, never from the name ([`Container::detect`]): a directory is a rosbag2
//! bag ([`crate::rosbag2`]: `metadata.yaml` with sqlite3 or MCAP storage files), a file opening with the MCAP magic is
//! MCAP ([`crate::mcap`]), one opening with `#ROSBAG V2.0` a ROS 1 bag ([`crate::bag`]), and a lone SQLite file a
//! rosbag2 storage file without its `metadata.yaml`. Message payloads are decoded elsewhere ([`crate::ros2`] for the
//! known types in CDR or ROS 1 serialization, [`crate::generic`] for any type whose definition the file carries).
//!
//! Damage — a truncated file, a record whose length runs past the end, a malformed field, a chunk that does not
//! decompress or fails its CRC, a message on an undefined channel, a bag without its index, an SQLite file or table
//! that cannot be read — is a [`Damage`] that names the byte offset of the record (or the table and row), the kind of
//! record and, inside a chunk, the offset of the chunk. By default it is an error; with [`ReadOptions::recover`] the
//! log holds every message read before the damage and the damage is kept in [`Log::damage`] with the number of bytes
//! left unread. A chunk whose decompression or CRC fails contributes no message at all (nothing in it can be
//! trusted); a bad record inside a good chunk keeps the messages before it. The whole log is indexed in memory before
//! it is sorted by log time: the memory used is the decompressed size of the compressed chunks (for SQLite storage,
//! of every payload) plus about 80 bytes per message.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use bytes::Bytes;

pub use crate::contents::{
    BAG_MAGIC, Channel, Container, DEFAULT_MAX_CHUNK_BYTES, Damage, DamageKind, LogError, MAGIC, Message, ReadOptions,
    SQLITE_MAGIC, Schema,
};
use crate::contents::{Contents, Place, map_file};

/// A log read into memory: its channels and its messages in log-time order.
#[derive(Debug, Clone)]
pub struct Log {
    /// The file's (or the rosbag2 directory's) name as given.
    pub file: String,
    /// How the messages were stored.
    pub container: Container,
    /// The profile in an MCAP header (`ros2`, `ros1`, …); `ros1` for a ROS 1 bag, `ros2` for a rosbag2 bag.
    pub profile: String,
    /// Schemas by id.
    pub schemas: BTreeMap<u16, Arc<Schema>>,
    /// Channels by id.
    pub channels: BTreeMap<u16, Arc<Channel>>,
    /// Messages sorted by log time (file order among equal times).
    pub messages: Vec<Message>,
    /// The damage reading stopped at, when reading with [`ReadOptions::recover`].
    pub damage: Option<Damage>,
    /// Bytes of the file not read because of the damage (0 without damage).
    pub unread_bytes: u64,
    /// Size of the file (or of a rosbag2 bag's storage files) in bytes.
    pub file_bytes: u64,
}

impl Log {
    /// Opens `path` — a file, memory-mapped, or a rosbag2 directory — detects its container and reads it.
    ///
    /// # Errors
    /// [`LogError::Open`] if the file cannot be opened or mapped; [`LogError::Damaged`] on damage unless
    /// `options.recover` (a file that is no known container is damaged at byte 0).
    pub fn open(path: impl AsRef<Path>, options: ReadOptions) -> Result<Log, LogError> {
        let path = path.as_ref();
        let name = path.display().to_string();
        if path.is_dir() {
            let (container, contents) = crate::rosbag2::read_dir(path, options)?;
            return Ok(Log::from_contents(contents, &name, container));
        }
        let open_error = |source| LogError::Open { path: name.clone(), source };
        let file = std::fs::File::open(path).map_err(open_error)?;
        let bytes = map_file(&file).map_err(open_error)?;
        if Container::detect(&bytes) == Some(Container::Rosbag2Sqlite3) {
            let contents = crate::rosbag2::read_sqlite(path, &name, options)?;
            return Ok(Log::from_contents(contents, &name, Container::Rosbag2Sqlite3));
        }
        Log::from_bytes(&name, bytes, options)
    }

    /// Reads an MCAP file or a ROS 1 bag held in memory (for instance a damaged copy made by a test), detected from
    /// its first bytes. `name` is used in errors. SQLite storage needs a path ([`Log::open`]).
    ///
    /// # Errors
    /// [`LogError::Damaged`] on damage unless `options.recover`.
    pub fn from_bytes(name: &str, bytes: Bytes, options: ReadOptions) -> Result<Log, LogError> {
        let (container, contents) = match Container::detect(&bytes) {
            Some(Container::Ros1Bag) => (Container::Ros1Bag, crate::bag::read(&bytes, options)),
            Some(Container::Rosbag2Sqlite3) => {
                let kind = DamageKind::Metadata("an SQLite storage file must be opened from its path".to_owned());
                let damage = Place::file(0).damage("magic", kind);
                return Err(LogError::Damaged { file: name.to_owned(), damage: Box::new(damage) });
            }
            _ => (Container::Mcap, crate::mcap::read(&bytes, options)),
        };
        let contents = contents.check(name, options)?;
        Ok(Log::from_contents(contents, name, container))
    }

    /// The log, its messages sorted by log time (file order among equal times).
    fn from_contents(contents: Contents, name: &str, container: Container) -> Log {
        let (damage, unread_bytes) = match contents.failure {
            None => (None, 0),
            Some((damage, resume)) => (Some(damage), contents.input_bytes.saturating_sub(resume)),
        };
        let mut messages = contents.messages;
        messages.sort_by_key(|message| message.log_time);
        Log {
            file: name.to_owned(),
            container,
            profile: contents.profile,
            schemas: contents.schemas,
            channels: contents.channels,
            messages,
            damage,
            unread_bytes,
            file_bytes: contents.input_bytes,
        }
    }

    /// Log time of the first and last message, if any.
    pub fn time_range(&self) -> Option<(u64, u64)> {
        Some((self.messages.first()?.log_time, self.messages.last()?.log_time))
    }
}
