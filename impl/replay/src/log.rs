//! Reading MCAP logs: the file is memory-mapped, its records are walked once from the start (chunks decompressed
//! one at a time, their CRCs checked), and the messages come out in log-time order, each with its channel and
//! schema and its payload as a [`Bytes`] view that borrows from the map (or from the chunk's decompressed buffer),
//! so a camera frame is never copied on the way in.
//!
//! Damage — a truncated file, a record whose length runs past the end, a malformed field, a chunk that does not
//! decompress or fails its CRC, a message on an undefined channel — is a [`Damage`] that names the byte offset of the
//! record, the kind of record and, inside a chunk, the offset of the chunk. By default it is an error; with
//! [`ReadOptions::recover`] the log holds every message read before the damage and the damage is kept in
//! [`Log::damage`] with the number of bytes left unread. A chunk whose decompression or CRC fails contributes no
//! message at all (nothing in it can be trusted); a bad record inside a good chunk keeps the messages before it.
//!
//! Only the MCAP format is interpreted here (records, chunks, compression `""`, `zstd`, `lz4`); message payloads are
//! decoded elsewhere ([`crate::ros2`]). The whole log is indexed in memory before it is sorted by log time: the
//! memory used is the decompressed size of the compressed chunks plus about 80 bytes per message.

use std::collections::BTreeMap;
use std::fmt;
use std::io::Read;
use std::path::Path;
use std::sync::Arc;

use bytes::Bytes;

/// The 8 bytes that open and close every MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

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
        /// Where and what.
        damage: Damage,
    },
}

/// Where a log is damaged, and how.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct Damage {
    /// Byte offset of the damaged record: in the file, or, when `chunk` is set, in the chunk's decompressed records.
    pub offset: u64,
    /// Byte offset in the file of the chunk the record is in, if any.
    pub chunk: Option<u64>,
    /// The kind of record (`message`, `chunk`, `channel`, …, or `magic`/`footer` for the file's frame).
    pub record: &'static str,
    /// What is wrong.
    pub kind: DamageKind,
}

impl fmt::Display for Damage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
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
    /// The file does not start (or end) with the MCAP magic.
    #[error("bad magic bytes (not an MCAP file, or a damaged one)")]
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
    #[error("unsupported compression `{0}` (supported: none, zstd, lz4)")]
    Compression(String),
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

/// A log read into memory: its channels and its messages in log-time order.
#[derive(Debug, Clone)]
pub struct Log {
    /// The file's name as given.
    pub file: String,
    /// The profile in the header (`ros2`, `ros1`, …).
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
    /// Size of the file in bytes.
    pub file_bytes: u64,
}

impl Log {
    /// Opens `path`, memory-maps it and reads it.
    ///
    /// # Errors
    /// [`LogError::Open`] if the file cannot be opened or mapped; [`LogError::Damaged`] on damage unless
    /// `options.recover`.
    pub fn open(path: impl AsRef<Path>, options: ReadOptions) -> Result<Log, LogError> {
        let path = path.as_ref();
        let open_error = |source| LogError::Open { path: path.display().to_string(), source };
        let file = std::fs::File::open(path).map_err(open_error)?;
        let bytes = map_file(&file).map_err(open_error)?;
        Log::from_bytes(&path.display().to_string(), bytes, options)
    }

    /// Reads a log held in memory (for instance a damaged copy made by a test). `name` is used in errors.
    ///
    /// # Errors
    /// [`LogError::Damaged`] on damage unless `options.recover`.
    pub fn from_bytes(name: &str, bytes: Bytes, options: ReadOptions) -> Result<Log, LogError> {
        let mut reader = Reader {
            options,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            messages: Vec::new(),
            profile: String::new(),
        };
        let file_bytes = bytes.len() as u64;
        let outcome = reader.read_file(&bytes);
        let (damage, unread_bytes) = match outcome {
            Ok(()) => (None, 0),
            Err((damage, resume)) => {
                if !options.recover {
                    return Err(LogError::Damaged { file: name.to_owned(), damage });
                }
                (Some(damage), file_bytes.saturating_sub(resume))
            }
        };
        let mut messages = reader.messages;
        messages.sort_by_key(|message| message.log_time);
        Ok(Log {
            file: name.to_owned(),
            profile: reader.profile,
            schemas: reader.schemas,
            channels: reader.channels,
            messages,
            damage,
            unread_bytes,
            file_bytes,
        })
    }

    /// Log time of the first and last message, if any.
    pub fn time_range(&self) -> Option<(u64, u64)> {
        Some((self.messages.first()?.log_time, self.messages.last()?.log_time))
    }
}

/// Maps a file read-only into memory as a [`Bytes`] that owns the map.
#[allow(unsafe_code)]
fn map_file(file: &std::fs::File) -> std::io::Result<Bytes> {
    // SAFETY: the map is read-only and lives as long as the returned `Bytes`. The one hazard of any file map is
    // another process truncating or rewriting the file while it is mapped (the project's logs are read-only
    // inputs); that is the documented contract of `Log::open`.
    let map = unsafe { memmap2::Mmap::map(file)? };
    Ok(Bytes::from_owner(map))
}

// Record opcodes.
const OP_HEADER: u8 = 0x01;
const OP_FOOTER: u8 = 0x02;
const OP_SCHEMA: u8 = 0x03;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;
const OP_DATA_END: u8 = 0x0F;

fn record_name(opcode: u8) -> &'static str {
    match opcode {
        0x01 => "header",
        0x02 => "footer",
        0x03 => "schema",
        0x04 => "channel",
        0x05 => "message",
        0x06 => "chunk",
        0x07 => "message index",
        0x08 => "chunk index",
        0x09 => "attachment",
        0x0A => "attachment index",
        0x0B => "statistics",
        0x0C => "metadata",
        0x0D => "metadata index",
        0x0E => "summary offset",
        0x0F => "data end",
        _ => "unknown",
    }
}

/// A failed read: the damage and the file offset up to which the file was consumed.
type Failure = (Damage, u64);

/// A cursor over a record's fields; errors are [`DamageKind`]s that the caller places.
struct Fields<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Fields<'a> {
    fn take(&mut self, field: &'static str, n: u64) -> Result<&'a [u8], DamageKind> {
        let available = (self.bytes.len() - self.pos) as u64;
        if n > available {
            return Err(DamageKind::Truncated { field, needed: n, available });
        }
        let n = n as usize;
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], DamageKind> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(field, N as u64)?);
        Ok(out)
    }

    fn u8(&mut self, field: &'static str) -> Result<u8, DamageKind> {
        Ok(self.array::<1>(field)?[0])
    }

    fn u16(&mut self, field: &'static str) -> Result<u16, DamageKind> {
        Ok(u16::from_le_bytes(self.array(field)?))
    }

    fn u32(&mut self, field: &'static str) -> Result<u32, DamageKind> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }

    fn u64(&mut self, field: &'static str) -> Result<u64, DamageKind> {
        Ok(u64::from_le_bytes(self.array(field)?))
    }

    fn string(&mut self, field: &'static str) -> Result<String, DamageKind> {
        let len = self.u32(field)?;
        let raw = self.take(field, u64::from(len))?;
        String::from_utf8(raw.to_vec()).map_err(|_| DamageKind::BadField { field, what: "not valid UTF-8".to_owned() })
    }

    /// A `u32`-prefixed byte array, as a range of the underlying buffer.
    fn bytes32(&mut self, field: &'static str) -> Result<std::ops::Range<usize>, DamageKind> {
        let len = self.u32(field)?;
        let start = self.pos;
        self.take(field, u64::from(len))?;
        Ok(start..self.pos)
    }

    fn string_map(&mut self, field: &'static str) -> Result<BTreeMap<String, String>, DamageKind> {
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

    fn rest(&self) -> std::ops::Range<usize> {
        self.pos..self.bytes.len()
    }
}

struct Reader {
    options: ReadOptions,
    schemas: BTreeMap<u16, Arc<Schema>>,
    channels: BTreeMap<u16, Arc<Channel>>,
    messages: Vec<Message>,
    profile: String,
}

/// Where a record sits: in the file, or inside a chunk's records.
#[derive(Clone, Copy)]
struct Place {
    offset: u64,
    chunk: Option<u64>,
}

impl Place {
    fn damage(self, record: &'static str, kind: DamageKind) -> Damage {
        Damage { offset: self.offset, chunk: self.chunk, record, kind }
    }
}

impl Reader {
    fn read_file(&mut self, file: &Bytes) -> Result<(), Failure> {
        let at_start = |kind| (Place { offset: 0, chunk: None }.damage("magic", kind), 0);
        if file.len() < MAGIC.len() {
            let available = file.len() as u64;
            return Err(at_start(DamageKind::Truncated { field: "magic", needed: 8, available }));
        }
        if &file[..MAGIC.len()] != MAGIC {
            return Err(at_start(DamageKind::BadMagic));
        }
        let mut pos = MAGIC.len();
        loop {
            let place = Place { offset: pos as u64, chunk: None };
            if pos == file.len() {
                return Err((place.damage("footer", DamageKind::NoFooter), pos as u64));
            }
            let (opcode, body) = match record_at(file, pos) {
                Ok(record) => record,
                Err((name, kind)) => return Err((place.damage(name, kind), pos as u64)),
            };
            let name = record_name(opcode);
            let end = body.end;
            let fail = |kind| (place.damage(name, kind), pos as u64);
            match opcode {
                OP_FOOTER => {
                    let tail = &file[end..];
                    if tail.len() < MAGIC.len() {
                        let available = tail.len() as u64;
                        let kind = DamageKind::Truncated { field: "closing magic", needed: 8, available };
                        return Err((Place { offset: end as u64, chunk: None }.damage("magic", kind), end as u64));
                    }
                    if &tail[..MAGIC.len()] != MAGIC {
                        return Err((
                            Place { offset: end as u64, chunk: None }.damage("magic", DamageKind::BadMagic),
                            end as u64,
                        ));
                    }
                    return Ok(());
                }
                OP_CHUNK => self.read_chunk(file, body, pos as u64).map_err(|damage| (damage, pos as u64))?,
                OP_DATA_END if self.options.check_crc => {
                    let mut fields = Fields { bytes: &file[body.clone()], pos: 0 };
                    let recorded = fields.u32("data section crc").map_err(fail)?;
                    if recorded != 0 {
                        let computed = crc32fast::hash(&file[..pos]);
                        if computed != recorded {
                            return Err(fail(DamageKind::Crc { what: "the data section", computed, recorded }));
                        }
                    }
                }
                _ => self.read_record(opcode, file, body, place, pos as u64).map_err(|damage| (damage, pos as u64))?,
            }
            pos = end;
        }
    }

    /// Reads a non-chunk record; `base` is where `buf` sits in the file (for message offsets).
    fn read_record(
        &mut self,
        opcode: u8,
        buf: &Bytes,
        body: std::ops::Range<usize>,
        place: Place,
        file_offset: u64,
    ) -> Result<(), Damage> {
        let name = record_name(opcode);
        let fail = |kind| place.damage(name, kind);
        let mut fields = Fields { bytes: &buf[body.clone()], pos: 0 };
        match opcode {
            OP_HEADER => {
                self.profile = fields.string("profile").map_err(fail)?;
            }
            OP_SCHEMA => {
                let id = fields.u16("id").map_err(fail)?;
                let schema_name = fields.string("name").map_err(fail)?;
                let encoding = fields.string("encoding").map_err(fail)?;
                let data = fields.bytes32("data").map_err(fail)?;
                if id == 0 {
                    return Err(fail(DamageKind::BadField { field: "id", what: "schema id 0 is reserved".into() }));
                }
                let data = buf.slice(body.start + data.start..body.start + data.end);
                self.schemas.entry(id).or_insert_with(|| Arc::new(Schema { id, name: schema_name, encoding, data }));
            }
            OP_CHANNEL => {
                let id = fields.u16("id").map_err(fail)?;
                let schema_id = fields.u16("schema id").map_err(fail)?;
                let topic = fields.string("topic").map_err(fail)?;
                let message_encoding = fields.string("message encoding").map_err(fail)?;
                let metadata = fields.string_map("metadata").map_err(fail)?;
                let schema = match schema_id {
                    0 => None,
                    _ => Some(
                        self.schemas
                            .get(&schema_id)
                            .cloned()
                            .ok_or_else(|| fail(DamageKind::UnknownSchema { channel: id, schema: schema_id }))?,
                    ),
                };
                self.channels
                    .entry(id)
                    .or_insert_with(|| Arc::new(Channel { id, topic, message_encoding, schema, metadata }));
            }
            OP_MESSAGE => {
                let channel_id = fields.u16("channel id").map_err(fail)?;
                let sequence = fields.u32("sequence").map_err(fail)?;
                let log_time = fields.u64("log time").map_err(fail)?;
                let publish_time = fields.u64("publish time").map_err(fail)?;
                let data = fields.rest();
                let channel = self
                    .channels
                    .get(&channel_id)
                    .cloned()
                    .ok_or_else(|| fail(DamageKind::UnknownChannel(channel_id)))?;
                self.messages.push(Message {
                    channel,
                    sequence,
                    log_time,
                    publish_time,
                    data: buf.slice(body.start + data.start..body.start + data.end),
                    file_offset,
                });
            }
            // Indexes, statistics, attachments, metadata and unknown records carry nothing a replay needs.
            _ => {}
        }
        Ok(())
    }

    fn read_chunk(&mut self, file: &Bytes, body: std::ops::Range<usize>, chunk_offset: u64) -> Result<(), Damage> {
        let place = Place { offset: chunk_offset, chunk: None };
        let fail = |kind| place.damage("chunk", kind);
        let mut fields = Fields { bytes: &file[body.clone()], pos: 0 };
        fields.u64("message start time").map_err(fail)?;
        fields.u64("message end time").map_err(fail)?;
        let declared = fields.u64("uncompressed size").map_err(fail)?;
        let crc = fields.u32("uncompressed crc").map_err(fail)?;
        let compression = fields.string("compression").map_err(fail)?;
        let records_len = fields.u64("records length").map_err(fail)?;
        let start = fields.pos;
        fields.take("records", records_len).map_err(fail)?;
        let compressed = file.slice(body.start + start..body.start + fields.pos);
        if declared > self.options.max_chunk_bytes {
            return Err(fail(DamageKind::TooLarge { declared, limit: self.options.max_chunk_bytes }));
        }
        let records = match compression.as_str() {
            "" => compressed,
            "zstd" | "lz4" => Bytes::from(decompress(&compression, &compressed, declared).map_err(fail)?),
            other => return Err(fail(DamageKind::Compression(other.to_owned()))),
        };
        if records.len() as u64 != declared {
            return Err(fail(DamageKind::Size { declared, found: records.len() as u64 }));
        }
        if self.options.check_crc && crc != 0 {
            let computed = crc32fast::hash(&records);
            if computed != crc {
                return Err(fail(DamageKind::Crc { what: "the chunk's records", computed, recorded: crc }));
            }
        }
        let mut pos = 0;
        while pos < records.len() {
            let place = Place { offset: pos as u64, chunk: Some(chunk_offset) };
            let (opcode, body) = record_at(&records, pos).map_err(|(name, kind)| place.damage(name, kind))?;
            let end = body.end;
            match opcode {
                OP_SCHEMA | OP_CHANNEL | OP_MESSAGE => self.read_record(opcode, &records, body, place, chunk_offset)?,
                OP_CHUNK | OP_HEADER | OP_FOOTER | OP_DATA_END => {
                    let what = "only schema, channel and message records may be inside a chunk".to_owned();
                    return Err(place.damage(record_name(opcode), DamageKind::BadField { field: "opcode", what }));
                }
                _ => {}
            }
            pos = end;
        }
        Ok(())
    }
}

/// The opcode and body range of the record at `pos`; on failure, the record's name (if its opcode could be read).
fn record_at(buf: &[u8], pos: usize) -> Result<(u8, std::ops::Range<usize>), (&'static str, DamageKind)> {
    let mut fields = Fields { bytes: buf, pos };
    let opcode = fields.u8("opcode").map_err(|kind| ("record", kind))?;
    let name = record_name(opcode);
    let len = fields.u64("record length").map_err(|kind| (name, kind))?;
    let start = fields.pos;
    fields.take("record body", len).map_err(|kind| (name, kind))?;
    Ok((opcode, start..fields.pos))
}

/// Decompresses a chunk, reading at most one byte more than declared (so a lying size cannot exhaust memory).
fn decompress(compression: &str, input: &[u8], declared: u64) -> Result<Vec<u8>, DamageKind> {
    let limit = declared.saturating_add(1);
    let mut out = Vec::with_capacity(declared.min(64 << 20) as usize);
    let failed =
        |error: std::io::Error| DamageKind::Decompress { compression: compression.to_owned(), what: error.to_string() };
    match compression {
        "zstd" => {
            let decoder = zstd::stream::read::Decoder::with_buffer(input).map_err(failed)?.single_frame();
            decoder.take(limit).read_to_end(&mut out).map_err(failed)?;
        }
        _ => {
            lz4_flex::frame::FrameDecoder::new(input).take(limit).read_to_end(&mut out).map_err(failed)?;
        }
    }
    Ok(out)
}
