//! Reading the messages of an MCAP file through the `mcap` crate.
//!
//! The file is walked once, front to back, by the crate's sans-I/O
//! [`LinearReader`]: the same path reads files with a summary and an index
//! (written by `ros2 bag record`, Foxglove, [`crate::write_mcap`]) and streaming
//! files without one, and a file whose tail is missing (a recording that was
//! killed or is still being written) gives every message before the cut, with
//! [`ReadSummary::truncated`] saying where it stopped. Chunks may be
//! uncompressed, `zstd` (the `mcap` crate's decoder, libzstd) or `lz4` (the
//! pure-Rust `lz4_flex`, registered here). Chunk, data-section and summary CRCs
//! are checked when the file has them. Metadata records are returned in
//! [`ReadSummary::metadata`]; attachments, indexes, statistics and private
//! records are skipped without being parsed.
//!
//! Errors name the record (its number in the file, counting from 1 in reading
//! order, records inside chunks included), its kind, the topic when there is
//! one, and what was expected. Nothing here panics on any input, and memory is
//! bounded by the input size and [`RECORD_LIMIT`].

use std::collections::HashMap;
use std::path::Path;

use mcap::records::{op, Record};
use mcap::sans_io::decompressor::{DecompressResult, Decompressor};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::McapError;

use crate::error::{Error, Result};

/// Largest record (and decompressed chunk record) accepted: 256 MiB.
pub const RECORD_LIMIT: usize = 256 << 20;

/// A channel of the file with its schema.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ChannelInfo {
    /// Channel id.
    pub id: u16,
    /// Topic name.
    pub topic: String,
    /// Message encoding (`json`, `cdr`, …).
    pub message_encoding: String,
    /// Schema name (`""` when the channel has no schema).
    pub schema_name: String,
    /// Schema encoding (`jsonschema`, `ros2msg`, …; `""` without a schema).
    pub schema_encoding: String,
    /// The channel's metadata (key/value pairs).
    pub metadata: std::collections::BTreeMap<String, String>,
}

/// Where a message was found, for errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MessageMeta {
    /// Record number (1-based, reading order).
    pub record: u64,
    /// Log time (ns).
    pub log_time: u64,
}

impl MessageMeta {
    /// `"record #12 (Message on `/x`, log time 5 ns)"`.
    pub fn describe(&self, topic: &str) -> String {
        format!(
            "record #{} (Message on `{topic}`, log time {} ns)",
            self.record, self.log_time
        )
    }
}

/// What a read went through.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(crate) struct ReadSummary {
    /// Records read (inside chunks included).
    pub records: u64,
    /// Message records read.
    pub messages: u64,
    /// `Some(why)` when the file ended before its end (no Footer and closing
    /// magic, or a cut record): every message before the cut was read.
    pub truncated: Option<String>,
    /// Metadata records: name → key/value pairs (a later record of the same
    /// name replaces an earlier one).
    pub metadata: std::collections::BTreeMap<String, std::collections::BTreeMap<String, String>>,
}

/// The name of a record kind, for errors.
fn kind(opcode: u8) -> &'static str {
    match opcode {
        op::HEADER => "Header",
        op::FOOTER => "Footer",
        op::SCHEMA => "Schema",
        op::CHANNEL => "Channel",
        op::MESSAGE => "Message",
        op::CHUNK => "Chunk",
        op::MESSAGE_INDEX => "Message Index",
        op::CHUNK_INDEX => "Chunk Index",
        op::ATTACHMENT => "Attachment",
        op::ATTACHMENT_INDEX => "Attachment Index",
        op::STATISTICS => "Statistics",
        op::METADATA => "Metadata",
        op::METADATA_INDEX => "Metadata Index",
        op::SUMMARY_OFFSET => "Summary Offset",
        op::DATA_END => "Data End",
        0x80..=0xFF => "private",
        _ => "reserved",
    }
}

pub(crate) fn input_err(problem: impl Into<String>) -> Error {
    Error::Value {
        what: "MCAP input".into(),
        problem: problem.into(),
    }
}

/// What a crate error means, with a hint where one helps.
fn explain(e: &McapError) -> String {
    match e {
        McapError::BadMagic => {
            "magic bytes missing or wrong (expected \\x89MCAP0\\r\\n at the start and the end; \
             not an MCAP file, or a damaged one)"
                .into()
        }
        McapError::BadChunkCrc { .. }
        | McapError::BadDataCrc { .. }
        | McapError::BadSummaryCrc { .. } => format!("{e}: corrupted data"),
        McapError::UnsupportedCompression(c) => format!(
            "chunk compressed with `{c}`; supported: none, `zstd`, `lz4` \
             (convert with `mcap convert --compression zstd`)"
        ),
        McapError::RecordTooLarge { opcode, len } => format!(
            "a {} record declares {len} bytes, more than the {} MiB accepted (corrupted data?)",
            kind(*opcode),
            RECORD_LIMIT >> 20
        ),
        McapError::Parse(p) => format!("malformed record: {}", one_line(&p.to_string())),
        other => one_line(&other.to_string()),
    }
}

/// binrw errors span several lines (with a backtrace-like trail): keep the first.
fn one_line(s: &str) -> String {
    s.lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .unwrap_or("")
        .to_string()
}

/// The `lz4` chunk decompressor: `lz4_flex`'s frame decoder (pure Rust).
///
/// It asks for the whole compressed chunk before its first call (its read hint
/// is unbounded; the reader caps it at the chunk's compressed size), then
/// decodes on demand into the caller's buffer, so the output is never larger
/// than what the chunk declares.
struct Lz4FlexDecoder {
    frame: Option<lz4_flex::frame::FrameDecoder<std::io::Cursor<Vec<u8>>>>,
}

impl Decompressor for Lz4FlexDecoder {
    fn next_read_size(&self) -> usize {
        if self.frame.is_none() {
            usize::MAX
        } else {
            0
        }
    }

    fn decompress(&mut self, src: &[u8], dst: &mut [u8]) -> mcap::McapResult<DecompressResult> {
        use std::io::Read;
        let consumed = if self.frame.is_none() {
            self.frame = Some(lz4_flex::frame::FrameDecoder::new(std::io::Cursor::new(
                src.to_vec(),
            )));
            src.len()
        } else {
            0
        };
        let wrote = match self.frame.as_mut() {
            Some(f) => f
                .read(dst)
                .map_err(|e| McapError::DecompressionError(format!("lz4: {e}")))?,
            None => 0,
        };
        Ok(DecompressResult { consumed, wrote })
    }

    fn reset(&mut self) -> mcap::McapResult<()> {
        self.frame = None;
        Ok(())
    }

    fn name(&self) -> &'static str {
        "lz4"
    }
}

/// Whether `bytes` ends like a complete MCAP file: a Footer record (20-byte
/// body) followed by the closing magic, as the `mcap` crate's [`LinearReader`]
/// reads them from the last 37 bytes. A file that does is not truncated, so a
/// record running past its end is damage, not a cut tail.
fn ends_with_footer(bytes: &[u8]) -> bool {
    const TAIL: usize = 1 + 8 + 20 + 8; // opcode, length, Footer body, magic
    let Some(tail) = bytes.len().checked_sub(TAIL).map(|s| &bytes[s..]) else {
        return false;
    };
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_check_finishes_after_end_magic(true)
            .with_record_length_limit(TAIL),
    );
    let mut fed = 0usize;
    let mut footer = false;
    while let Some(event) = reader.next_event() {
        match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let n = need.min(tail.len() - fed);
                reader.insert(n).copy_from_slice(&tail[fed..fed + n]);
                reader.notify_read(n);
                fed += n;
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                footer = opcode == op::FOOTER && data.len() == 20;
            }
            Err(_) => return false,
        }
    }
    footer && fed == tail.len()
}

/// Walks every record of `bytes`, calling `on_message(channel, meta, data)` for
/// each Message record (`data` the message payload). See the module docs.
pub(crate) fn for_each_message(
    bytes: &[u8],
    on_message: impl FnMut(&ChannelInfo, MessageMeta, &[u8]) -> Result<()>,
) -> Result<ReadSummary> {
    for_each_message_watched(bytes, &crate::watch::Unwatched, on_message)
}

/// [`for_each_message`] that stops with [`Error::Interrupted`] soon after
/// `watch` is cancelled (it looks at every record and every read request).
pub(crate) fn for_each_message_watched(
    bytes: &[u8],
    watch: &dyn crate::watch::Watch,
    mut on_message: impl FnMut(&ChannelInfo, MessageMeta, &[u8]) -> Result<()>,
) -> Result<ReadSummary> {
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_check_finishes_after_end_magic(true)
            .with_record_length_limit(RECORD_LIMIT),
    );
    reader
        .add_decompressor(Lz4FlexDecoder { frame: None })
        .map_err(|e| input_err(e.to_string()))?;
    // schema id -> (name, encoding)
    let mut schemas: HashMap<u16, (String, String)> = HashMap::new();
    let mut channels: HashMap<u16, ChannelInfo> = HashMap::new();
    let mut sum = ReadSummary::default();
    let mut fed = 0usize;
    let mut last = "none (at the start of the file)".to_string();
    let mut seen_footer = false;
    while let Some(event) = reader.next_event() {
        watch.check()?;
        let event = match event {
            Ok(ev) => ev,
            Err(McapError::UnexpectedEof) if sum.records > 0 && ends_with_footer(bytes) => {
                return Err(input_err(format!(
                    "after record #{} ({last}): a record runs past the end of the file, \
                     although the file ends with a Footer and the closing magic \
                     (a damaged length field: corrupted data)",
                    sum.records
                )))
            }
            Err(McapError::UnexpectedEof) if sum.records > 0 => {
                sum.truncated = Some(format!(
                    "the file ends {} (after record #{}, {last}; {} messages read): \
                     a truncated or still-open recording",
                    if seen_footer {
                        "inside its closing magic bytes"
                    } else {
                        "before its Footer record"
                    },
                    sum.records,
                    sum.messages
                ));
                break;
            }
            Err(McapError::UnexpectedEof) => {
                return Err(input_err(format!(
                    "the file ends after {} bytes, before its first record \
                     (an MCAP file starts with 8 magic bytes and a Header record)",
                    bytes.len()
                )))
            }
            Err(e) => {
                return Err(input_err(format!(
                    "after record #{} ({last}): {}",
                    sum.records,
                    explain(&e)
                )))
            }
        };
        let (opcode, data) = match event {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(bytes.len() - fed);
                reader.insert(n).copy_from_slice(&bytes[fed..fed + n]);
                reader.notify_read(n);
                fed += n;
                continue;
            }
            LinearReadEvent::Record { opcode, data } => (opcode, data),
        };
        sum.records += 1;
        let record = sum.records;
        let at = |what: &str| format!("record #{record} ({what})");
        if record == 1 && opcode != op::HEADER {
            return Err(input_err(format!(
                "{}: the first record must be a Header",
                at(kind(opcode))
            )));
        }
        match opcode {
            op::SCHEMA | op::CHANNEL | op::MESSAGE | op::METADATA => {}
            op::FOOTER => {
                seen_footer = true;
                last = kind(opcode).into();
                continue;
            }
            _ => {
                // Header, indexes, attachments, statistics, private
                // records: not needed, not parsed.
                last = kind(opcode).into();
                continue;
            }
        }
        let parsed = mcap::parse_record(opcode, data).map_err(|e| {
            input_err(format!(
                "{}: cannot parse it: {}",
                at(kind(opcode)),
                explain(&e)
            ))
        })?;
        match parsed {
            Record::Schema { header, .. } => {
                last = format!("Schema `{}`", header.name);
                if header.id == 0 {
                    return Err(input_err(format!(
                        "{}: schema id 0 is reserved for \"no schema\"",
                        at(&last)
                    )));
                }
                let entry = (header.name, header.encoding);
                if let Some(prev) = schemas.get(&header.id) {
                    if *prev != entry {
                        return Err(input_err(format!(
                            "{}: schema id {} redefined (was `{}`)",
                            at(&last),
                            header.id,
                            prev.0
                        )));
                    }
                }
                schemas.insert(header.id, entry);
            }
            Record::Channel(ch) => {
                last = format!("Channel `{}`", ch.topic);
                let (schema_name, schema_encoding) = if ch.schema_id == 0 {
                    (String::new(), String::new())
                } else {
                    schemas.get(&ch.schema_id).cloned().ok_or_else(|| {
                        input_err(format!(
                            "{}: refers to schema id {}, which no earlier Schema record defines",
                            at(&last),
                            ch.schema_id
                        ))
                    })?
                };
                let info = ChannelInfo {
                    id: ch.id,
                    topic: ch.topic,
                    message_encoding: ch.message_encoding,
                    schema_name,
                    schema_encoding,
                    metadata: ch.metadata,
                };
                if let Some(prev) = channels.get(&ch.id) {
                    if *prev != info {
                        return Err(input_err(format!(
                            "{}: channel id {} redefined (was `{}`)",
                            at(&last),
                            ch.id,
                            prev.topic
                        )));
                    }
                }
                channels.insert(ch.id, info);
            }
            Record::Message { header, data } => {
                sum.messages += 1;
                let Some(ch) = channels.get(&header.channel_id) else {
                    return Err(input_err(format!(
                        "{}: refers to channel id {}, which no earlier Channel record defines",
                        at("Message"),
                        header.channel_id
                    )));
                };
                last = format!("Message on `{}`", ch.topic);
                on_message(
                    ch,
                    MessageMeta {
                        record,
                        log_time: header.log_time,
                    },
                    &data,
                )?;
            }
            Record::Metadata(m) => {
                last = format!("Metadata `{}`", m.name);
                sum.metadata.insert(m.name, m.metadata);
            }
            _ => {}
        }
    }
    if sum.records == 0 {
        return Err(input_err("the file holds no record"));
    }
    Ok(sum)
}

/// Errors unless `bytes` starts with the MCAP magic.
pub(crate) fn check_magic(bytes: &[u8]) -> Result<()> {
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(input_err(
            "not an MCAP file (the leading magic bytes \\x89MCAP0\\r\\n are missing)",
        ));
    }
    Ok(())
}

/// The bytes of a file, or an error naming it.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::Io(format!("cannot read {}: {e}", path.display())))
}

/// Puts the file name into an input error.
pub fn name_file(e: Error, path: &Path) -> Error {
    match e {
        Error::Value { what, problem } => Error::Value {
            what: format!("{what} {}", path.display()),
            problem,
        },
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small complete file: Header, one Schema, Channel and Message, summary, Footer.
    fn small_file() -> Vec<u8> {
        let mut cur = std::io::Cursor::new(Vec::new());
        let mut w = mcap::Writer::new(&mut cur).unwrap();
        let s = w.add_schema("s", "jsonschema", b"{}").unwrap();
        let c = w
            .add_channel(s, "/x", "json", &std::collections::BTreeMap::new())
            .unwrap();
        let header = mcap::records::MessageHeader {
            channel_id: c,
            sequence: 1,
            log_time: 5,
            publish_time: 5,
        };
        w.write_to_known_channel(&header, b"{}").unwrap();
        w.finish().unwrap();
        drop(w);
        cur.into_inner()
    }

    #[test]
    fn the_footer_check_reads_the_tail_through_the_crate() {
        let bytes = small_file();
        assert!(ends_with_footer(&bytes));
        let n = bytes.len();
        // Cut anywhere, or a damaged Footer opcode, length or closing magic: no.
        for cut in [0, 8, n - 1, n - 8, n - 20] {
            assert!(!ends_with_footer(&bytes[..cut]), "cut at {cut}");
        }
        for pos in [n - 37, n - 36, n - 29, n - 1] {
            let mut bad = bytes.clone();
            bad[pos] ^= 0x40;
            assert!(!ends_with_footer(&bad), "byte {pos} damaged");
        }
        // A footer's body bytes (summary offsets, CRC) are not judged here.
        let mut body = bytes.clone();
        body[n - 20] ^= 0x01;
        assert!(ends_with_footer(&body));
    }

    #[test]
    fn a_record_running_past_a_complete_file_is_damage_not_a_cut() {
        let bytes = small_file();
        let mut read = Vec::new();
        for_each_message(&bytes, |ch, meta, data| {
            read.push((ch.topic.clone(), meta.log_time, data.to_vec()));
            Ok(())
        })
        .unwrap();
        assert_eq!(read, vec![("/x".to_string(), 5, b"{}".to_vec())]);
        // The record after the Header (a Chunk: the writer's default) given a
        // length that runs past the end of the file.
        let header_len = u64::from_le_bytes(bytes[9..17].try_into().unwrap()) as usize;
        let next = 8 + 9 + header_len;
        assert_eq!(bytes[next], op::CHUNK);
        let mut bad = bytes.clone();
        bad[next + 1..next + 9].copy_from_slice(&(bytes.len() as u64).to_le_bytes());
        let e = for_each_message(&bad, |_, _, _| Ok(()))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "a record runs past the end of the file, although the file ends with a Footer"
            ),
            "{e}"
        );
        // The same file cut before its Footer: the messages read, marked truncated.
        let cut = &bytes[..bytes.len() - 40];
        let sum = for_each_message(cut, |_, _, _| Ok(())).unwrap();
        assert!(sum.truncated.is_some());
    }

    #[test]
    fn lz4_decoder_round_trips_a_frame() {
        use std::io::Write;
        let text: Vec<u8> = (0..10_000u32)
            .flat_map(|i| (i % 251).to_le_bytes())
            .collect();
        let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
        enc.write_all(&text).unwrap();
        let compressed = enc.finish().unwrap();
        let mut d = Lz4FlexDecoder { frame: None };
        assert_eq!(d.next_read_size(), usize::MAX);
        let mut out = vec![0u8; text.len()];
        let mut pos = 0;
        let first = d.decompress(&compressed, &mut out[..7]).unwrap();
        assert_eq!(first.consumed, compressed.len());
        pos += first.wrote;
        while pos < out.len() {
            let r = d.decompress(&[], &mut out[pos..]).unwrap();
            assert!(r.wrote > 0);
            pos += r.wrote;
        }
        assert_eq!(out, text);
        d.reset().unwrap();
        assert_eq!(d.next_read_size(), usize::MAX);
        assert!(d.decompress(&compressed[..20], &mut out).is_err());
    }
}
