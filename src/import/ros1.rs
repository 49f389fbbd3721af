//! ROS 1 bags (format 2.0): records streamed through a buffered reader, one
//! chunk decompressed at a time (none, bz2 or lz4), so memory is bounded by
//! the messages kept and one chunk, never by the bag.
//!
//! Why not the `rosbag` crate: it maps the whole file and asserts (panics) on
//! some malformed lengths; a bag is untrusted input here, and the format is
//! small (a record is `u32` header length, `name=value` fields, `u32` data
//! length, data), so a streaming reader with errors as values is less code
//! than guarding a library.

use std::collections::HashMap;
use std::io::{BufReader, Read};
use std::path::Path;

use super::LoadError;
use super::timeline::{Recording, TopicChoice, Topics};

/// The first line of every ROS 1 bag.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

/// Largest record or decompressed chunk accepted (a corrupt length must not allocate gigabytes).
const MAX_RECORD: usize = 1 << 30;

const OP_MESSAGE: u8 = 0x02;
const OP_CHUNK: u8 = 0x05;
const OP_CONNECTION: u8 = 0x07;

/// Read the bag at `path`: the messages of every topic gyropath can use.
pub fn read(path: &Path, choice: &TopicChoice) -> Result<(Recording, Topics), LoadError> {
    let (f, file) = super::open_file(path)?;
    read_from(BufReader::with_capacity(1 << 20, f), &file, choice)
}

/// Read a bag from any reader; `file` names it in errors.
pub fn read_from(
    mut input: impl Read,
    file: &str,
    choice: &TopicChoice,
) -> Result<(Recording, Topics), LoadError> {
    let err = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    let mut magic = [0u8; 13];
    input
        .read_exact(&mut magic)
        .map_err(|_| err("not a ROS 1 bag: the file is shorter than its magic line".into()))?;
    if magic != MAGIC {
        return Err(err(
            "not a ROS 1 bag version 2.0 (no '#ROSBAG V2.0' line)".into()
        ));
    }
    let mut bag = Bag {
        file,
        recording: Recording::new(file),
        connections: HashMap::new(),
        offset: MAGIC.len() as u64,
    };
    let mut header = Vec::new();
    let mut data = Vec::new();
    let mut chunk = Vec::new();
    loop {
        match bag.next_record(&mut input, &mut header, &mut data)? {
            Next::Record => {}
            Next::End => break,
            Next::Cut => {
                bag.recording.cut_at = Some(bag.offset);
                break;
            }
        }
        let fields = Fields::parse(&header).map_err(|m| bag.corrupt(&m))?;
        match fields.op().map_err(|m| bag.corrupt(&m))? {
            OP_CHUNK => {
                let compression = fields.text("compression").map_err(|m| bag.corrupt(&m))?;
                let size = fields.u32("size").map_err(|m| bag.corrupt(&m))? as usize;
                decompress(&compression, &data, size, &mut chunk).map_err(|m| bag.corrupt(&m))?;
                bag.chunk_records(&chunk, choice)?;
            }
            OP_CONNECTION => bag.connection(&fields, &data)?,
            OP_MESSAGE => bag.message(&fields, &data, choice)?,
            _ => {}
        }
    }
    let topics = bag.recording.choose(choice)?;
    Ok((bag.recording, topics))
}

/// What [`Bag::next_record`] found.
enum Next {
    Record,
    End,
    Cut,
}

/// A connection: its topic and message type.
struct Connection {
    topic: String,
    type_name: String,
}

struct Bag<'f> {
    file: &'f str,
    recording: Recording,
    connections: HashMap<u32, Connection>,
    /// Byte offset of the record being read (for messages).
    offset: u64,
}

impl Bag<'_> {
    fn corrupt(&self, message: &str) -> LoadError {
        LoadError::File {
            file: self.file.to_string(),
            message: format!("corrupt record at byte {}: {message}", self.offset),
        }
    }

    /// Read one record's header and data: [`Next::End`] at a clean end of
    /// the file, [`Next::Cut`] where it ends inside the record (a recorder
    /// killed, a disk full, a copy cut short: the records before it stand,
    /// as the bag's own `rosbag reindex` would keep them).
    fn next_record(
        &mut self,
        input: &mut impl Read,
        header: &mut Vec<u8>,
        data: &mut Vec<u8>,
    ) -> Result<Next, LoadError> {
        let mut len = [0u8; 4];
        match read_full(input, &mut len) {
            Ok(0) => return Ok(Next::End),
            Ok(4) => {}
            Ok(_) => return Ok(Next::Cut),
            Err(error) => {
                return Err(LoadError::Io {
                    file: self.file.to_string(),
                    error,
                });
            }
        }
        if !self.read_block(input, u32::from_le_bytes(len) as usize, header)? {
            return Ok(Next::Cut);
        }
        let mut len = [0u8; 4];
        if read_full(input, &mut len).map_err(|error| LoadError::Io {
            file: self.file.to_string(),
            error,
        })? != 4
            || !self.read_block(input, u32::from_le_bytes(len) as usize, data)?
        {
            return Ok(Next::Cut);
        }
        self.offset += 8 + header.len() as u64 + data.len() as u64;
        Ok(Next::Record)
    }

    /// Read `n` bytes into `out`; `false` where the file ends before them.
    fn read_block(
        &self,
        input: &mut impl Read,
        n: usize,
        out: &mut Vec<u8>,
    ) -> Result<bool, LoadError> {
        if n > MAX_RECORD {
            return Err(self.corrupt(&format!("a length of {n} bytes")));
        }
        out.clear();
        let got = input
            .by_ref()
            .take(n as u64)
            .read_to_end(out)
            .map_err(|error| LoadError::Io {
                file: self.file.to_string(),
                error,
            })?;
        Ok(got == n)
    }

    /// The records inside a decompressed chunk: connections and messages.
    fn chunk_records(&mut self, chunk: &[u8], choice: &TopicChoice) -> Result<(), LoadError> {
        let mut pos = 0usize;
        let block = |pos: &mut usize| -> Option<&[u8]> {
            let len = chunk.get(*pos..*pos + 4)?;
            let n = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
            let b = chunk.get(*pos + 4..(*pos + 4).checked_add(n)?)?;
            *pos += 4 + n;
            Some(b)
        };
        while pos < chunk.len() {
            let (Some(h), Some(d)) = (block(&mut pos), block(&mut pos)) else {
                return Err(self.corrupt("a record inside a chunk runs past the chunk's end"));
            };
            let fields = Fields::parse(h).map_err(|m| self.corrupt(&m))?;
            match fields.op().map_err(|m| self.corrupt(&m))? {
                OP_CONNECTION => self.connection(&fields, d)?,
                OP_MESSAGE => self.message(&fields, d, choice)?,
                _ => {}
            }
        }
        Ok(())
    }

    fn connection(&mut self, fields: &Fields, data: &[u8]) -> Result<(), LoadError> {
        let id = fields.u32("conn").map_err(|m| self.corrupt(&m))?;
        if self.connections.contains_key(&id) {
            return Ok(());
        }
        let topic = fields.text("topic").map_err(|m| self.corrupt(&m))?;
        let inner = Fields::parse(data).map_err(|m| self.corrupt(&m))?;
        let type_name = inner.text("type").map_err(|m| self.corrupt(&m))?;
        self.recording.add_topic(&topic, &type_name);
        self.connections.insert(id, Connection { topic, type_name });
        Ok(())
    }

    fn message(
        &mut self,
        fields: &Fields,
        data: &[u8],
        choice: &TopicChoice,
    ) -> Result<(), LoadError> {
        let id = fields.u32("conn").map_err(|m| self.corrupt(&m))?;
        let time = fields.time("time").map_err(|m| self.corrupt(&m))?;
        let Some(c) = self.connections.get(&id) else {
            return Err(self.corrupt(&format!(
                "a message on connection {id}, which no connection record declares"
            )));
        };
        self.recording
            .push_ros1(&c.topic, &c.type_name, data, time, choice)
    }
}

/// `read_exact` that tells a clean end (0 bytes) from a short read.
pub(super) fn read_full(input: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match input.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Decompress a chunk into `out`, which must come to `size` bytes.
fn decompress(
    compression: &str,
    data: &[u8],
    size: usize,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    if size > MAX_RECORD {
        return Err(format!("a chunk of {size} bytes"));
    }
    out.clear();
    out.reserve(size.min(1 << 26));
    let limit = size as u64 + 1;
    let got = match compression {
        "none" => {
            out.extend_from_slice(data);
            data.len()
        }
        "bz2" => bzip2::read::BzDecoder::new(data)
            .take(limit)
            .read_to_end(out)
            .map_err(|e| format!("bz2 chunk cannot be decompressed: {e}"))?,
        "lz4" => lz4_flex::frame::FrameDecoder::new(data)
            .take(limit)
            .read_to_end(out)
            .map_err(|e| format!("lz4 chunk cannot be decompressed: {e}"))?,
        other => return Err(format!("unknown chunk compression '{other}'")),
    };
    if got != size {
        return Err(format!(
            "chunk decompresses to {got} bytes, its header says {size}"
        ));
    }
    Ok(())
}

/// The `name=value` fields of a record header.
struct Fields<'a>(Vec<(&'a [u8], &'a [u8])>);

impl<'a> Fields<'a> {
    fn parse(mut h: &'a [u8]) -> Result<Self, String> {
        let mut out = Vec::new();
        while !h.is_empty() {
            let len = h.get(..4).ok_or("a header field length is cut off")?;
            let n = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
            let field = h
                .get(4..4usize.saturating_add(n))
                .ok_or("a header field runs past the header")?;
            let eq = field
                .iter()
                .position(|&b| b == b'=')
                .ok_or("a header field has no '='")?;
            out.push((&field[..eq], &field[eq + 1..]));
            h = &h[4 + n..];
        }
        Ok(Self(out))
    }

    fn get(&self, name: &str) -> Result<&'a [u8], String> {
        self.0
            .iter()
            .find(|(k, _)| *k == name.as_bytes())
            .map(|&(_, v)| v)
            .ok_or_else(|| format!("its header has no '{name}' field"))
    }

    fn op(&self) -> Result<u8, String> {
        match self.get("op")? {
            [b] => Ok(*b),
            _ => Err("its 'op' field is not one byte".into()),
        }
    }

    fn u32(&self, name: &str) -> Result<u32, String> {
        match self.get(name)? {
            [a, b, c, d] => Ok(u32::from_le_bytes([*a, *b, *c, *d])),
            _ => Err(format!("its '{name}' field is not 4 bytes")),
        }
    }

    /// A `time` field: `u32` seconds, `u32` nanoseconds, as nanoseconds.
    fn time(&self, name: &str) -> Result<i64, String> {
        match self.get(name)? {
            [a, b, c, d, e, f, g, h] => Ok(u32::from_le_bytes([*a, *b, *c, *d]) as i64
                * 1_000_000_000
                + u32::from_le_bytes([*e, *f, *g, *h]) as i64),
            _ => Err(format!("its '{name}' field is not 8 bytes")),
        }
    }

    fn text(&self, name: &str) -> Result<String, String> {
        String::from_utf8(self.get(name)?.to_vec())
            .map_err(|_| format!("its '{name}' field is not UTF-8"))
    }
}

/// Writes ROS 1 bags (bare messages, or chunks: none, bz2 or lz4), for tests and benchmarks.
pub struct BagWriter {
    pub bytes: Vec<u8>,
    connections: Vec<(String, String)>,
    /// Chunked: the compression and the records of the open chunk.
    chunk: Option<(&'static str, Vec<u8>)>,
}

impl Default for BagWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl BagWriter {
    pub fn new() -> Self {
        let mut bytes = MAGIC.to_vec();
        // A bag header record with no index (readers that stream need none).
        let mut header = Vec::new();
        push_field(&mut header, b"op", &[0x03]);
        push_field(&mut header, b"index_pos", &0u64.to_le_bytes());
        push_field(&mut header, b"conn_count", &0u32.to_le_bytes());
        push_field(&mut header, b"chunk_count", &0u32.to_le_bytes());
        push_record(&mut bytes, &header, &[b' '; 16]);
        Self {
            bytes,
            connections: Vec::new(),
            chunk: None,
        }
    }

    /// A writer that packs its records into chunks compressed with
    /// `compression` ("none", "bz2" or "lz4"), as `rosbag record` does.
    pub fn chunked(compression: &'static str) -> Self {
        Self {
            chunk: Some((compression, Vec::new())),
            ..Self::new()
        }
    }

    /// Close the open chunk (a chunked writer's records are in `bytes` only after this).
    pub fn flush_chunk(&mut self) -> std::io::Result<()> {
        let Some((compression, records)) = self.chunk.as_mut() else {
            return Ok(());
        };
        if records.is_empty() {
            return Ok(());
        }
        let raw = std::mem::take(records);
        let data = match *compression {
            "bz2" => {
                use std::io::Write as _;
                let mut e = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::default());
                e.write_all(&raw)?;
                e.finish()?
            }
            "lz4" => {
                use std::io::Write as _;
                let mut e = lz4_flex::frame::FrameEncoder::new(Vec::new());
                e.write_all(&raw)?;
                e.finish().map_err(std::io::Error::other)?
            }
            _ => raw.clone(),
        };
        let mut header = Vec::new();
        push_field(&mut header, b"op", &[OP_CHUNK]);
        push_field(&mut header, b"compression", compression.as_bytes());
        push_field(&mut header, b"size", &(raw.len() as u32).to_le_bytes());
        push_record(&mut self.bytes, &header, &data);
        Ok(())
    }

    /// Where the next record goes: the open chunk, or the bag itself.
    fn records(&mut self) -> &mut Vec<u8> {
        match self.chunk.as_mut() {
            Some((_, records)) => records,
            None => &mut self.bytes,
        }
    }

    /// Write a message on `topic` of `type_name`, declaring the connection the first time.
    pub fn message(&mut self, topic: &str, type_name: &str, time: f64, data: &[u8]) {
        let id = match self.connections.iter().position(|(t, _)| t == topic) {
            Some(i) => i as u32,
            None => {
                let id = self.connections.len() as u32;
                self.connections.push((topic.into(), type_name.into()));
                let mut header = Vec::new();
                push_field(&mut header, b"op", &[OP_CONNECTION]);
                push_field(&mut header, b"conn", &id.to_le_bytes());
                push_field(&mut header, b"topic", topic.as_bytes());
                let mut body = Vec::new();
                push_field(&mut body, b"topic", topic.as_bytes());
                push_field(&mut body, b"type", type_name.as_bytes());
                push_field(&mut body, b"md5sum", b"*");
                push_record(self.records(), &header, &body);
                id
            }
        };
        let mut header = Vec::new();
        push_field(&mut header, b"op", &[OP_MESSAGE]);
        push_field(&mut header, b"conn", &id.to_le_bytes());
        let sec = time.floor();
        let mut t = (sec as u32).to_le_bytes().to_vec();
        t.extend((((time - sec) * 1e9) as u32).to_le_bytes());
        push_field(&mut header, b"time", &t);
        push_record(self.records(), &header, data);
    }
}

fn push_field(out: &mut Vec<u8>, name: &[u8], value: &[u8]) {
    out.extend(((name.len() + 1 + value.len()) as u32).to_le_bytes());
    out.extend(name);
    out.push(b'=');
    out.extend(value);
}

fn push_record(out: &mut Vec<u8>, header: &[u8], data: &[u8]) {
    out.extend((header.len() as u32).to_le_bytes());
    out.extend(header);
    out.extend((data.len() as u32).to_le_bytes());
    out.extend(data);
}
