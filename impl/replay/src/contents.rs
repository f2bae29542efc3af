//! What every container reader shares: the log's parts (schemas, channels, messages), the container kinds and their
//! magic bytes, read options, damage and where it is, the contents a reader gathers, and the helpers the readers use
//! (fields of a record, decompression, mapping a file). The readers ([`crate::mcap`], [`crate::bag`],
//! [`crate::rosbag2`]) depend on this module; [`crate::log`] dispatches to them and re-exports what users need.

use std::collections::BTreeMap;
use std::fmt;
use std::io::Read;
use std::sync::Arc;

use bytes::Bytes;

/// The 8 bytes that open and close every MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// The line that opens a ROS 1 bag of format 2.0.
pub const BAG_MAGIC: &[u8; 13] = b"#ROSBAG V2.0\n";

/// The 16 bytes that open an SQLite database file.
pub const SQLITE_MAGIC: &[u8; 16] = b"SQLite format 3\0";

/// A log's container: how its messages are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Container {
    /// An MCAP file (ROS 2 `cdr` or ROS 1 `ros1` messages).
    Mcap,
    /// A ROS 1 bag, format 2.0.
    Ros1Bag,
    /// A rosbag2 directory (or a lone storage file) with sqlite3 storage.
    Rosbag2Sqlite3,
    /// A rosbag2 directory with MCAP storage.
    Rosbag2Mcap,
}

impl Container {
    /// Its name in summaries and manifests: `mcap`, `ros1 bag`, `rosbag2 sqlite3`, `rosbag2 mcap`.
    pub fn name(self) -> &'static str {
        match self {
            Container::Mcap => "mcap",
            Container::Ros1Bag => "ros1 bag",
            Container::Rosbag2Sqlite3 => "rosbag2 sqlite3",
            Container::Rosbag2Mcap => "rosbag2 mcap",
        }
    }

    /// The container of a file from its first bytes (`None` if they are no container's); a directory is always a
    /// rosbag2 bag, whose storage [`crate::rosbag2`] reads from its `metadata.yaml`.
    pub fn detect(head: &[u8]) -> Option<Container> {
        if head.starts_with(MAGIC) {
            Some(Container::Mcap)
        } else if head.starts_with(BAG_MAGIC) {
            Some(Container::Ros1Bag)
        } else if head.starts_with(SQLITE_MAGIC) {
            Some(Container::Rosbag2Sqlite3)
        } else {
            None
        }
    }
}

/// Decompressed chunks larger than this are refused by default (see [`ReadOptions::max_chunk_bytes`]).
pub const DEFAULT_MAX_CHUNK_BYTES: u64 = 1 << 30;

/// Why a log cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The file could not be opened or mapped.
    #[error("cannot open {path}")]
    Open {
        /// The path given.
        path: String,
        /// The operating system's error (printed by error chains, so not repeated in the message).
        #[source]
        source: std::io::Error,
    },
    /// The file is damaged (and recovery was not asked for).
    #[error("{file}: {damage}")]
    Damaged {
        /// The file's name as given.
        file: String,
        /// Where and what (boxed: a damage is large and errors are rare).
        damage: Box<Damage>,
    },
}

/// Where a log is damaged, and how.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct Damage {
    /// Byte offset of the damaged record: in the file, or, when `chunk` is set, in the chunk's decompressed records.
    pub offset: u64,
    /// Byte offset in the file of the chunk the record is in, if any.
    pub chunk: Option<u64>,
    /// The kind of record (`message`, `chunk`, `channel`, `connection`, …, or `magic`/`footer` for the file's
    /// frame).
    pub record: &'static str,
    /// For SQLite storage, the table the damage is in; `offset` is then the row id (0 for the table as a whole).
    pub table: Option<&'static str>,
    /// What is wrong.
    pub kind: DamageKind,
}

impl fmt::Display for Damage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(table) = self.table {
            return match self.offset {
                0 => write!(f, "table `{table}`: {}", self.kind),
                row => write!(f, "{} at row {row} of table `{table}`: {}", self.record, self.kind),
            };
        }
        match self.chunk {
            Some(chunk) => write!(
                f,
                "{} record at byte {} of the chunk at file byte {}: {}",
                self.record, self.offset, chunk, self.kind
            ),
            None => write!(f, "{} record at byte {}: {}", self.record, self.offset, self.kind),
        }
    }
}

/// What is wrong at a [`Damage`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DamageKind {
    /// The file does not start with the magic of a container this reader knows (or an MCAP file does not end with
    /// its magic).
    #[error("bad magic bytes (not an MCAP file, a ROS 1 bag v2.0 or a rosbag2 bag, or a damaged one)")]
    BadMagic,
    /// Fewer bytes are left than the record or field needs.
    #[error("truncated: `{field}` needs {needed} bytes, {available} left")]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Bytes needed.
        needed: u64,
        /// Bytes left.
        available: u64,
    },
    /// A field holds an impossible value.
    #[error("field `{field}`: {what}")]
    BadField {
        /// The field.
        field: &'static str,
        /// What is wrong with it.
        what: String,
    },
    /// A message refers to a channel id that no channel record defined before it.
    #[error("message refers to undefined channel {0}")]
    UnknownChannel(u16),
    /// A channel refers to a schema id that no schema record defined before it.
    #[error("channel {channel} refers to undefined schema {schema}")]
    UnknownSchema {
        /// The channel id.
        channel: u16,
        /// The schema id.
        schema: u16,
    },
    /// The chunk uses a compression this reader does not know.
    #[error("unsupported compression `{found}` (supported: {supported})")]
    Compression {
        /// The compression the chunk names.
        found: String,
        /// The compressions this container's reader supports.
        supported: &'static str,
    },
    /// The chunk does not decompress.
    #[error("{compression} decompression failed: {what}")]
    Decompress {
        /// The compression.
        compression: String,
        /// The decompressor's message.
        what: String,
    },
    /// The decompressed chunk is not of the declared size.
    #[error("decompressed to {found} bytes, {declared} declared")]
    Size {
        /// Declared size.
        declared: u64,
        /// Size found (at most one byte more than declared is read).
        found: u64,
    },
    /// A CRC does not match.
    #[error("CRC mismatch over {what}: computed {computed:#010x}, recorded {recorded:#010x}")]
    Crc {
        /// What the CRC covers.
        what: &'static str,
        /// Computed CRC-32.
        computed: u32,
        /// CRC-32 in the file.
        recorded: u32,
    },
    /// The records end before the footer (a truncated file, or a writer that crashed).
    #[error("the file ends without a footer record")]
    NoFooter,
    /// A ROS 1 bag without a usable index (the recording was not closed, or the file was cut before its index).
    #[error("no index: {0} (`rosbag reindex` repairs it; --recover replays the chunks without it)")]
    NoIndex(String),
    /// SQLite could not read the storage.
    #[error("sqlite: {0}")]
    Sqlite(String),
    /// A rosbag2 directory's `metadata.yaml` is missing or names no storage this reader knows.
    #[error("{0}")]
    Metadata(String),
    /// A chunk declares more decompressed bytes than allowed.
    #[error("declares {declared} decompressed bytes, more than the limit of {limit}")]
    TooLarge {
        /// Declared size.
        declared: u64,
        /// The limit.
        limit: u64,
    },
}

/// A schema record: how the messages of a channel are encoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Schema {
    /// Schema id (never 0).
    pub id: u16,
    /// Schema name, e.g. `sensor_msgs/msg/Image`.
    pub name: String,
    /// Schema encoding, e.g. `ros2msg`.
    pub encoding: String,
    /// The schema text.
    pub data: Bytes,
}

/// A channel record: a topic and the encoding of its messages.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Channel {
    /// Channel id.
    pub id: u16,
    /// Topic name, e.g. `/cam0/image_raw`.
    pub topic: String,
    /// Message encoding, e.g. `cdr` (ROS 2) or `ros1`.
    pub message_encoding: String,
    /// The schema, if the channel has one (schema id 0 means none).
    pub schema: Option<Arc<Schema>>,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
}

impl Channel {
    /// The schema's name, or `""` for a schemaless channel.
    pub fn type_name(&self) -> &str {
        self.schema.as_ref().map_or("", |schema| schema.name.as_str())
    }
}

/// One message of a log.
#[derive(Debug, Clone)]
pub struct Message {
    /// Its channel.
    pub channel: Arc<Channel>,
    /// The writer's sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time: u64,
    /// Publish time, ns.
    pub publish_time: u64,
    /// The payload: a view into the memory map or a decompressed chunk, not a copy.
    pub data: Bytes,
    /// Byte offset in the file of the message record, or of the chunk holding it.
    pub file_offset: u64,
}

/// How to read a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadOptions {
    /// Keep what was read before damage instead of failing.
    pub recover: bool,
    /// Check chunk and data-section CRCs where the file records them (non-zero).
    pub check_crc: bool,
    /// Largest decompressed chunk accepted, in bytes.
    pub max_chunk_bytes: u64,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions { recover: false, check_crc: true, max_chunk_bytes: DEFAULT_MAX_CHUNK_BYTES }
    }
}

/// What a container's reader gathered, and where it stopped if it met damage.
#[derive(Debug, Default)]
pub(crate) struct Contents {
    /// The MCAP profile, or the one the container implies.
    pub profile: String,
    /// Schemas by id.
    pub schemas: BTreeMap<u16, Arc<Schema>>,
    /// Channels by id.
    pub channels: BTreeMap<u16, Arc<Channel>>,
    /// Messages in file order.
    pub messages: Vec<Message>,
    /// The damage reading stopped at, with the byte up to which the input was consumed.
    pub failure: Option<Failure>,
    /// Size of the input in bytes.
    pub input_bytes: u64,
}

impl Contents {
    /// An error if reading met damage and `options.recover` is off.
    pub fn check(self, name: &str, options: ReadOptions) -> Result<Contents, LogError> {
        match &self.failure {
            Some((damage, _)) if !options.recover => {
                Err(LogError::Damaged { file: name.to_owned(), damage: Box::new(damage.clone()) })
            }
            _ => Ok(self),
        }
    }
}

/// Maps a file read-only into memory as a [`Bytes`] that owns the map.
#[allow(unsafe_code)]
pub(crate) fn map_file(file: &std::fs::File) -> std::io::Result<Bytes> {
    // SAFETY: the map is read-only and lives as long as the returned `Bytes`. The one hazard of any file map is
    // another process truncating or rewriting the file while it is mapped (the project's logs are read-only
    // inputs); that is the documented contract of `Log::open`.
    let map = unsafe { memmap2::Mmap::map(file)? };
    Ok(Bytes::from_owner(map))
}

/// A failed read: the damage and the file offset up to which the file was consumed.
pub(crate) type Failure = (Damage, u64);

/// A cursor over a record's fields; errors are [`DamageKind`]s that the caller places.
pub(crate) struct Fields<'a> {
    pub bytes: &'a [u8],
    pub pos: usize,
}

impl<'a> Fields<'a> {
    pub fn take(&mut self, field: &'static str, n: u64) -> Result<&'a [u8], DamageKind> {
        let available = (self.bytes.len() - self.pos) as u64;
        if n > available {
            return Err(DamageKind::Truncated { field, needed: n, available });
        }
        let n = n as usize;
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    pub fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], DamageKind> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(field, N as u64)?);
        Ok(out)
    }

    pub fn u8(&mut self, field: &'static str) -> Result<u8, DamageKind> {
        Ok(self.array::<1>(field)?[0])
    }

    pub fn u16(&mut self, field: &'static str) -> Result<u16, DamageKind> {
        Ok(u16::from_le_bytes(self.array(field)?))
    }

    pub fn u32(&mut self, field: &'static str) -> Result<u32, DamageKind> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }

    pub fn u64(&mut self, field: &'static str) -> Result<u64, DamageKind> {
        Ok(u64::from_le_bytes(self.array(field)?))
    }

    pub fn string(&mut self, field: &'static str) -> Result<String, DamageKind> {
        let len = self.u32(field)?;
        let raw = self.take(field, u64::from(len))?;
        String::from_utf8(raw.to_vec()).map_err(|_| DamageKind::BadField { field, what: "not valid UTF-8".to_owned() })
    }

    /// A `u32`-prefixed byte array, as a range of the underlying buffer.
    pub fn bytes32(&mut self, field: &'static str) -> Result<std::ops::Range<usize>, DamageKind> {
        let len = self.u32(field)?;
        let start = self.pos;
        self.take(field, u64::from(len))?;
        Ok(start..self.pos)
    }

    pub fn string_map(&mut self, field: &'static str) -> Result<BTreeMap<String, String>, DamageKind> {
        let len = self.u32(field)?;
        let raw = self.take(field, u64::from(len))?;
        let mut inner = Fields { bytes: raw, pos: 0 };
        let mut map = BTreeMap::new();
        while inner.pos < raw.len() {
            let key = inner.string(field)?;
            let value = inner.string(field)?;
            map.insert(key, value);
        }
        Ok(map)
    }

    pub fn rest(&self) -> std::ops::Range<usize> {
        self.pos..self.bytes.len()
    }
}

/// Where a record sits: in the file, or inside a chunk's records.
#[derive(Clone, Copy)]
pub(crate) struct Place {
    pub offset: u64,
    pub chunk: Option<u64>,
}

impl Place {
    /// A place in the file.
    pub fn file(offset: u64) -> Place {
        Place { offset, chunk: None }
    }

    /// The damage of a `record` at this place.
    pub fn damage(self, record: &'static str, kind: DamageKind) -> Damage {
        Damage { offset: self.offset, chunk: self.chunk, record, table: None, kind }
    }
}

/// Decompresses a chunk (`zstd`, `bz2`, else `lz4` frames), reading at most one byte more than declared (so a lying size cannot exhaust memory).
pub(crate) fn decompress(compression: &str, input: &[u8], declared: u64) -> Result<Vec<u8>, DamageKind> {
    let limit = declared.saturating_add(1);
    let mut out = Vec::with_capacity(declared.min(64 << 20) as usize);
    let failed =
        |error: std::io::Error| DamageKind::Decompress { compression: compression.to_owned(), what: error.to_string() };
    match compression {
        "zstd" => {
            let decoder = zstd::stream::read::Decoder::with_buffer(input).map_err(failed)?.single_frame();
            decoder.take(limit).read_to_end(&mut out).map_err(failed)?;
        }
        "bz2" => {
            bzip2::read::BzDecoder::new(input).take(limit).read_to_end(&mut out).map_err(failed)?;
        }
        _ => {
            lz4_flex::frame::FrameDecoder::new(input).take(limit).read_to_end(&mut out).map_err(failed)?;
        }
    }
    Ok(out)
}
