//! The MCAP reader: the file's records are walked once from the start (chunks decompressed one at a time, their CRCs
//! checked), and every schema, channel and message is gathered into `Contents`; [`crate::log`] sorts the messages
//! and decides what damage means. Only the MCAP format is interpreted here (records, chunks, compression `""`,
//! `zstd`, `lz4`).

use bytes::Bytes;
use std::sync::Arc;

use crate::contents::{
    Channel, Contents, Damage, DamageKind, Failure, Fields, Message, Place, ReadOptions, Schema, decompress,
};

pub use crate::contents::MAGIC;

/// Reads an MCAP file held in memory; damage is kept in [`Contents::failure`].
pub(crate) fn read(file: &Bytes, options: ReadOptions) -> Contents {
    let mut reader = Reader { options, contents: Contents { input_bytes: file.len() as u64, ..Contents::default() } };
    if let Err(failure) = reader.read_file(file) {
        reader.contents.failure = Some(failure);
    }
    reader.contents
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

struct Reader {
    options: ReadOptions,
    contents: Contents,
}

impl Reader {
    fn read_file(&mut self, file: &Bytes) -> Result<(), Failure> {
        let at_start = |kind| (Place::file(0).damage("magic", kind), 0);
        if file.len() < MAGIC.len() {
            let available = file.len() as u64;
            return Err(at_start(DamageKind::Truncated { field: "magic", needed: 8, available }));
        }
        if &file[..MAGIC.len()] != MAGIC {
            return Err(at_start(DamageKind::BadMagic));
        }
        let mut pos = MAGIC.len();
        loop {
            let place = Place::file(pos as u64);
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
                        return Err((Place::file(end as u64).damage("magic", kind), end as u64));
                    }
                    if &tail[..MAGIC.len()] != MAGIC {
                        return Err((Place::file(end as u64).damage("magic", DamageKind::BadMagic), end as u64));
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
                self.contents.profile = fields.string("profile").map_err(fail)?;
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
                self.contents
                    .schemas
                    .entry(id)
                    .or_insert_with(|| Arc::new(Schema { id, name: schema_name, encoding, data }));
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
                        self.contents
                            .schemas
                            .get(&schema_id)
                            .cloned()
                            .ok_or_else(|| fail(DamageKind::UnknownSchema { channel: id, schema: schema_id }))?,
                    ),
                };
                self.contents
                    .channels
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
                    .contents
                    .channels
                    .get(&channel_id)
                    .cloned()
                    .ok_or_else(|| fail(DamageKind::UnknownChannel(channel_id)))?;
                self.contents.messages.push(Message {
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
        let place = Place::file(chunk_offset);
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
            other => {
                return Err(fail(DamageKind::Compression { found: other.to_owned(), supported: "none, zstd, lz4" }));
            }
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
