//! The ROS 1 bag reader (format 2.0): the file's records are walked once from the start — the bag header, chunks
//! (uncompressed, `bz2` or `lz4`) holding connection and message-data records, the index records after each chunk, and
//! the index section the bag header points to (connections and chunk infos) — and every connection and message is
//! gathered into `Contents` in the same form as an MCAP file's: a connection is a channel (`ros1` message encoding)
//! with a schema named by its ROS 1 type (`sensor_msgs/Imu`, encoding `ros1msg`) whose text is the connection's
//! `message_definition`.
//!
//! A record is a `u32`-prefixed header of `u32`-prefixed `name=value` fields (`op` says the kind) and a
//! `u32`-prefixed data block. The walk does not need the index, so a bag whose index is missing (a recording that was
//! not closed: `index_pos` 0) or cut off still yields its messages; that is damage ([`DamageKind::NoIndex`]) all the
//! same, reported after every chunk was read, and `--recover` keeps what was read.

use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::Arc;

use bytes::Bytes;

use crate::contents::{
    BAG_MAGIC, Channel, Contents, Damage, DamageKind, Failure, Fields, Message, Place, ReadOptions, Schema, decompress,
};

const OP_MESSAGE_DATA: u8 = 0x02;
const OP_BAG_HEADER: u8 = 0x03;
const OP_INDEX_DATA: u8 = 0x04;
const OP_CHUNK: u8 = 0x05;
const OP_CHUNK_INFO: u8 = 0x06;
const OP_CONNECTION: u8 = 0x07;

fn record_name(op: u8) -> &'static str {
    match op {
        OP_MESSAGE_DATA => "message data",
        OP_BAG_HEADER => "bag header",
        OP_INDEX_DATA => "index data",
        OP_CHUNK => "chunk",
        OP_CHUNK_INFO => "chunk info",
        OP_CONNECTION => "connection",
        _ => "unknown",
    }
}

/// Reads a ROS 1 bag held in memory; damage is kept in [`Contents::failure`].
pub(crate) fn read(file: &Bytes, options: ReadOptions) -> Contents {
    let contents = Contents { profile: "ros1".to_owned(), input_bytes: file.len() as u64, ..Contents::default() };
    let mut reader = BagReader { options, contents, sequence: 0, chunk_infos: 0, index_seen: false };
    if let Err(failure) = reader.read_file(file) {
        reader.contents.failure = Some(failure);
    }
    reader.contents
}

/// One record: its op, its header fields and the range of its data block; `end` is where the next record starts.
struct Record<'a> {
    op: u8,
    fields: BTreeMap<&'a [u8], &'a [u8]>,
    data: Range<usize>,
    end: usize,
}

impl<'a> Record<'a> {
    fn field(&self, name: &'static str) -> Result<&'a [u8], DamageKind> {
        self.fields.get(name.as_bytes()).copied().ok_or_else(|| DamageKind::BadField {
            field: name,
            what: format!("missing from the {} record's header", record_name(self.op)),
        })
    }

    fn u32(&self, name: &'static str) -> Result<u32, DamageKind> {
        Fields { bytes: self.field(name)?, pos: 0 }.u32(name)
    }

    fn u64(&self, name: &'static str) -> Result<u64, DamageKind> {
        Fields { bytes: self.field(name)?, pos: 0 }.u64(name)
    }

    fn text(&self, name: &'static str) -> Result<String, DamageKind> {
        text(name, self.field(name)?)
    }
}

fn text(field: &'static str, raw: &[u8]) -> Result<String, DamageKind> {
    String::from_utf8(raw.to_vec()).map_err(|_| DamageKind::BadField { field, what: "not valid UTF-8".to_owned() })
}

/// The `name=value` fields of a header block.
fn header_fields(raw: &[u8]) -> Result<BTreeMap<&[u8], &[u8]>, DamageKind> {
    let mut cursor = Fields { bytes: raw, pos: 0 };
    let mut fields = BTreeMap::new();
    while cursor.pos < raw.len() {
        let len = cursor.u32("header field length")?;
        let field = cursor.take("header field", u64::from(len))?;
        let Some(equals) = field.iter().position(|&byte| byte == b'=') else {
            let what = "a header field without `=`".to_owned();
            return Err(DamageKind::BadField { field: "header field", what });
        };
        fields.insert(&field[..equals], &field[equals + 1..]);
    }
    Ok(fields)
}

/// The record at `pos`; on failure, the record's name if its header could be read.
fn record_at(buf: &[u8], pos: usize) -> Result<Record<'_>, (&'static str, DamageKind)> {
    let mut cursor = Fields { bytes: buf, pos };
    let header_len = cursor.u32("header length").map_err(|kind| ("record", kind))?;
    let header = cursor.take("record header", u64::from(header_len)).map_err(|kind| ("record", kind))?;
    let fields = header_fields(header).map_err(|kind| ("record", kind))?;
    let op = match fields.get(b"op".as_slice()) {
        Some(&[op]) => *op,
        _ => {
            let what = "the header has no one-byte `op` field".to_owned();
            return Err(("record", DamageKind::BadField { field: "op", what }));
        }
    };
    let name = record_name(op);
    let data_len = cursor.u32("data length").map_err(|kind| (name, kind))?;
    let start = cursor.pos;
    cursor.take("record data", u64::from(data_len)).map_err(|kind| (name, kind))?;
    Ok(Record { op, fields, data: start..cursor.pos, end: cursor.pos })
}

/// Damage of a `record` at file offset `pos`, the file read up to there.
fn fail_at(pos: usize, record: &'static str, kind: DamageKind) -> Failure {
    (Place::file(pos as u64).damage(record, kind), pos as u64)
}

/// The magic line and the bag header: the header's `index_pos`, `chunk_count`, and where the next record starts.
fn read_bag_header(file: &[u8]) -> Result<(u64, u32, usize), Failure> {
    if !file.starts_with(BAG_MAGIC) {
        let kind = if file.starts_with(b"#ROSBAG V") {
            let version = file[9..file.len().min(16)].split(|&b| b == b'\n').next().unwrap_or_default();
            let what = format!("version {} (only 2.0 is read)", String::from_utf8_lossy(version));
            DamageKind::BadField { field: "version", what }
        } else {
            DamageKind::BadMagic
        };
        return Err(fail_at(0, "magic", kind));
    }
    let at = BAG_MAGIC.len();
    let header = record_at(file, at).map_err(|(name, kind)| fail_at(at, name, kind))?;
    if header.op != OP_BAG_HEADER {
        let what = format!("the first record is a {} record, not the bag header", record_name(header.op));
        return Err(fail_at(at, "bag header", DamageKind::BadField { field: "op", what }));
    }
    let index_pos = header.u64("index_pos").map_err(|kind| fail_at(at, "bag header", kind))?;
    let chunk_count = header.u32("chunk_count").map_err(|kind| fail_at(at, "bag header", kind))?;
    Ok((index_pos, chunk_count, header.end))
}

struct BagReader {
    options: ReadOptions,
    contents: Contents,
    /// Messages read so far (a message's `sequence`: bags keep none of their own).
    sequence: u32,
    /// Chunk-info records met (the index lists one per chunk).
    chunk_infos: u32,
    /// Whether a record started at the bag header's `index_pos`.
    index_seen: bool,
}

impl BagReader {
    fn read_file(&mut self, file: &Bytes) -> Result<(), Failure> {
        let (index_pos, chunk_count, mut pos) = read_bag_header(file)?;
        while pos < file.len() {
            self.index_seen |= pos as u64 == index_pos;
            let record = record_at(file, pos).map_err(|(name, kind)| fail_at(pos, name, kind))?;
            self.read_record(file, &record, pos).map_err(|damage| (damage, pos as u64))?;
            pos = record.end;
        }
        match self.index_problem(index_pos, chunk_count, file.len()) {
            Some(what) => {
                Err((Place::file(BAG_MAGIC.len() as u64).damage("bag header", DamageKind::NoIndex(what)), pos as u64))
            }
            None => Ok(()),
        }
    }

    /// What is wrong with the index, once every record was read: `None` if it is where the bag header says and
    /// lists every chunk.
    fn index_problem(&self, index_pos: u64, chunk_count: u32, file_bytes: usize) -> Option<String> {
        if index_pos == 0 {
            Some("the bag header's index_pos is 0: the recording was not closed".to_owned())
        } else if index_pos >= file_bytes as u64 {
            let what = "is past the end of the file";
            Some(format!("the bag header's index_pos {index_pos} {what} ({file_bytes} bytes): it was cut"))
        } else if !self.index_seen {
            Some(format!("no record starts at the bag header's index_pos {index_pos}"))
        } else if self.chunk_infos != chunk_count {
            Some(format!("the index lists {} chunks, the bag header {chunk_count}", self.chunk_infos))
        } else {
            None
        }
    }

    /// Reads a top-level record at file offset `pos`.
    fn read_record(&mut self, file: &Bytes, record: &Record<'_>, pos: usize) -> Result<(), Damage> {
        let fail = |kind| Place::file(pos as u64).damage(record_name(record.op), kind);
        match record.op {
            OP_CHUNK => self.read_chunk(file, record, pos),
            OP_CONNECTION => self.read_connection(file, record).map_err(fail),
            OP_MESSAGE_DATA => self.read_message(file, record, pos as u64).map_err(fail),
            OP_CHUNK_INFO => {
                self.chunk_infos += 1;
                Ok(())
            }
            OP_INDEX_DATA => Ok(()),
            op => Err(fail(DamageKind::BadField { field: "op", what: format!("unknown record op {op:#04x}") })),
        }
    }

    fn read_chunk(&mut self, file: &Bytes, record: &Record<'_>, pos: usize) -> Result<(), Damage> {
        let chunk_place = Place::file(pos as u64);
        let fail = |kind| chunk_place.damage("chunk", kind);
        let compression = record.text("compression").map_err(fail)?;
        let declared = u64::from(record.u32("size").map_err(fail)?);
        if declared > self.options.max_chunk_bytes {
            return Err(fail(DamageKind::TooLarge { declared, limit: self.options.max_chunk_bytes }));
        }
        let compressed = file.slice(record.data.clone());
        let records = match compression.as_str() {
            "none" => compressed,
            "bz2" | "lz4" => Bytes::from(decompress(&compression, &compressed, declared).map_err(fail)?),
            other => {
                return Err(fail(DamageKind::Compression { found: other.to_owned(), supported: "none, bz2, lz4" }));
            }
        };
        if records.len() as u64 != declared {
            return Err(fail(DamageKind::Size { declared, found: records.len() as u64 }));
        }
        let mut inner = 0;
        while inner < records.len() {
            let place = Place { offset: inner as u64, chunk: Some(pos as u64) };
            let record = record_at(&records, inner).map_err(|(name, kind)| place.damage(name, kind))?;
            let outcome = match record.op {
                OP_CONNECTION => self.read_connection(&records, &record),
                OP_MESSAGE_DATA => self.read_message(&records, &record, pos as u64),
                op => {
                    let what = format!("a {} record (op {op:#04x}) inside a chunk", record_name(op));
                    Err(DamageKind::BadField { field: "op", what })
                }
            };
            outcome.map_err(|kind| place.damage(record_name(record.op), kind))?;
            inner = record.end;
        }
        Ok(())
    }

    /// A connection record: a channel with its own schema (the first record of a connection id wins).
    fn read_connection(&mut self, buf: &Bytes, record: &Record<'_>) -> Result<(), DamageKind> {
        let id = connection_id(record)?;
        if self.contents.channels.contains_key(&id) {
            return Ok(());
        }
        let topic = record.text("topic")?;
        let block = &buf[record.data.clone()];
        let fields = header_fields(block)?;
        let get = |name: &'static str| {
            fields.get(name.as_bytes()).copied().ok_or_else(|| DamageKind::BadField {
                field: name,
                what: "missing from the connection's data".to_owned(),
            })
        };
        let type_name = text("type", get("type")?)?;
        let definition = get("message_definition")?;
        let offset = definition.as_ptr() as usize - buf.as_ptr() as usize;
        let data = buf.slice(offset..offset + definition.len());
        let schema_id = id.checked_add(1).ok_or_else(|| too_many(u32::from(id)))?;
        let schema = Arc::new(Schema { id: schema_id, name: type_name, encoding: "ros1msg".to_owned(), data });
        let mut metadata = BTreeMap::new();
        for name in ["md5sum", "callerid", "latching"] {
            if let Some(value) = fields.get(name.as_bytes()) {
                metadata.insert(name.to_owned(), String::from_utf8_lossy(value).into_owned());
            }
        }
        let channel =
            Channel { id, topic, message_encoding: "ros1".to_owned(), schema: Some(schema.clone()), metadata };
        self.contents.schemas.insert(schema_id, schema);
        self.contents.channels.insert(id, Arc::new(channel));
        Ok(())
    }

    /// A message-data record; `file_offset` is that of the record, or of the chunk holding it.
    fn read_message(&mut self, buf: &Bytes, record: &Record<'_>, file_offset: u64) -> Result<(), DamageKind> {
        let id = connection_id(record)?;
        let channel = self.contents.channels.get(&id).cloned().ok_or(DamageKind::UnknownChannel(id))?;
        let time = record.u64("time")?;
        let (sec, nsec) = (time & 0xFFFF_FFFF, time >> 32);
        let log_time = sec * 1_000_000_000 + nsec;
        self.contents.messages.push(Message {
            channel,
            sequence: self.sequence,
            log_time,
            publish_time: log_time,
            data: buf.slice(record.data.clone()),
            file_offset,
        });
        self.sequence = self.sequence.wrapping_add(1);
        Ok(())
    }
}

/// A record's `conn` field, as a channel id.
fn connection_id(record: &Record<'_>) -> Result<u16, DamageKind> {
    let conn = record.u32("conn")?;
    u16::try_from(conn).ok().filter(|&id| id < u16::MAX).ok_or_else(|| too_many(conn))
}

fn too_many(conn: u32) -> DamageKind {
    let what = format!("connection id {conn}: this reader takes ids below {}", u16::MAX);
    DamageKind::BadField { field: "conn", what }
}
