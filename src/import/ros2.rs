//! ROS 2 bags: a rosbag2 folder (`metadata.yaml` beside its storage files) or
//! a bare `.mcap`. MCAP is streamed through the `mcap` crate's sans-io linear
//! reader (zstd and lz4 chunks decompressed one at a time), so memory is
//! bounded by the messages kept and one chunk, never by the bag; messages are
//! CDR, decoded by [`super::wire`].

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::LoadError;
use super::timeline::{Recording, TopicChoice, Topics};

/// The first bytes of every MCAP file.
pub const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// Largest record accepted outside chunks (a corrupt length must not allocate gigabytes).
const MAX_RECORD: usize = 1 << 30;

/// Read a rosbag2 folder or an MCAP file.
pub fn read(path: &Path, choice: &TopicChoice) -> Result<(Recording, Topics), LoadError> {
    let files = if path.is_dir() {
        storage_files(path)?
    } else {
        vec![path.to_path_buf()]
    };
    let source = path.display().to_string();
    let mut rec = Recording::new(&source);
    for f in &files {
        let file = f.display().to_string();
        let input = std::fs::File::open(f).map_err(|error| LoadError::Io {
            file: file.clone(),
            error,
        })?;
        read_mcap(
            std::io::BufReader::with_capacity(1 << 20, input),
            &file,
            &mut rec,
            choice,
        )?;
    }
    let topics = rec.choose(choice)?;
    Ok((rec, topics))
}

/// The storage files of a rosbag2 folder: those `metadata.yaml` lists under
/// `relative_file_paths`, else every `.mcap` in it; a `.db3` (SQLite) bag is refused by name.
fn storage_files(dir: &Path) -> Result<Vec<PathBuf>, LoadError> {
    let folder = dir.display().to_string();
    let err = |message: String| LoadError::File {
        file: folder.clone(),
        message,
    };
    let meta = dir.join("metadata.yaml");
    let mut files = Vec::new();
    if let Ok(text) = std::fs::read_to_string(&meta) {
        let mut listing = false;
        for line in text.lines() {
            let trimmed = line.trim();
            if trimmed.starts_with("relative_file_paths:") {
                listing = true;
                continue;
            }
            if listing {
                match trimmed.strip_prefix("- ") {
                    Some(name) => files.push(dir.join(name.trim().trim_matches(['"', '\'']))),
                    None => listing = false,
                }
            }
        }
        if text.contains("storage_identifier: sqlite3") {
            return Err(err(
                "a rosbag2 folder in SQLite storage (.db3); gyropath reads MCAP storage: convert with `ros2 bag convert` to mcap".into(),
            ));
        }
    }
    if files.is_empty() {
        let listed = std::fs::read_dir(dir).map_err(|error| LoadError::Io {
            file: folder.clone(),
            error,
        })?;
        files = listed
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension()
                    .is_some_and(|x| x.eq_ignore_ascii_case("mcap"))
            })
            .collect();
        files.sort();
    }
    if files.is_empty() {
        return Err(err(
            "neither a rosbag2 folder with MCAP storage nor a folder holding .mcap files".into(),
        ));
    }
    for f in &files {
        if !f.is_file() {
            return Err(err(format!(
                "metadata.yaml lists '{}', which is not in the folder",
                f.display()
            )));
        }
        if f.extension().is_some_and(|x| x.eq_ignore_ascii_case("db3")) {
            return Err(err(format!(
                "'{}' is SQLite storage; gyropath reads MCAP storage: convert with `ros2 bag convert`",
                f.display()
            )));
        }
    }
    Ok(files)
}

/// A channel: its topic, message type and encoding.
struct Channel {
    topic: String,
    type_name: String,
    cdr: bool,
}

/// Stream one MCAP file's messages into `rec`.
pub fn read_mcap(
    mut input: impl Read,
    file: &str,
    rec: &mut Recording,
    choice: &TopicChoice,
) -> Result<(), LoadError> {
    let corrupt = |e: &dyn std::fmt::Display| LoadError::File {
        file: file.to_string(),
        message: format!("not a readable MCAP file: {e}"),
    };
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_record_length_limit(MAX_RECORD)
            .with_emit_chunks(true),
    );
    let mut schemas: HashMap<u16, String> = HashMap::new();
    let mut channels: HashMap<u16, Channel> = HashMap::new();
    let mut record = |opcode: u8, data: &[u8], rec: &mut Recording| -> Result<(), LoadError> {
        match mcap::parse_record(opcode, data).map_err(|e| corrupt(&e))? {
            mcap::records::Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            mcap::records::Record::Channel(c) => {
                let type_name = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                rec.add_topic(&c.topic, &type_name);
                channels.insert(
                    c.id,
                    Channel {
                        topic: c.topic,
                        type_name,
                        cdr: c.message_encoding == "cdr",
                    },
                );
            }
            mcap::records::Record::Message { header, data } => {
                let Some(c) = channels.get(&header.channel_id) else {
                    return Err(corrupt(&format!(
                        "a message on channel {}, which no channel record declares",
                        header.channel_id
                    )));
                };
                if c.cdr {
                    let log_ns = i64::try_from(header.log_time).unwrap_or(i64::MAX);
                    rec.push_cdr(&c.topic, &c.type_name, &data, log_ns, choice)?;
                }
            }
            _ => {}
        }
        Ok(())
    };
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| corrupt(&e))? {
            LinearReadEvent::ReadRequest(need) => {
                let buf = reader.insert(need);
                let n = loop {
                    match input.read(buf) {
                        Ok(n) => break n,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        Err(error) => {
                            return Err(LoadError::Io {
                                file: file.to_string(),
                                error,
                            });
                        }
                    }
                };
                reader.notify_read(n);
            }
            LinearReadEvent::Record { data, opcode } if opcode == CHUNK_OPCODE => {
                let chunk = match mcap::parse_record(opcode, data).map_err(|e| corrupt(&e))? {
                    mcap::records::Record::Chunk { header, data } => {
                        decompress_chunk(&header, &data).map_err(|e| corrupt(&e))?
                    }
                    _ => continue,
                };
                for (op, body) in chunk_records(&chunk).map_err(|e| corrupt(&e))? {
                    record(op, body, rec)?;
                }
            }
            LinearReadEvent::Record { data, opcode } => record(opcode, data, rec)?,
        }
    }
    Ok(())
}

/// The MCAP chunk record's opcode.
const CHUNK_OPCODE: u8 = 0x06;

/// A chunk's records, decompressed into a buffer of exactly the size its
/// header claims (never more than [`MAX_RECORD`]), its CRC checked when it
/// has one.
fn decompress_chunk(header: &mcap::records::ChunkHeader, data: &[u8]) -> Result<Vec<u8>, String> {
    let size = usize::try_from(header.uncompressed_size)
        .ok()
        .filter(|&s| s <= MAX_RECORD)
        .ok_or_else(|| format!("a chunk claims {} bytes", header.uncompressed_size))?;
    let out = match header.compression.as_str() {
        "" => data.to_vec(),
        "zstd" => zstd::bulk::decompress(data, size).map_err(|e| format!("zstd chunk: {e}"))?,
        "lz4" => {
            let mut out = Vec::with_capacity(size);
            let mut dec = lz4_flex::frame::FrameDecoder::new(data).take(size as u64 + 1);
            dec.read_to_end(&mut out)
                .map_err(|e| format!("lz4 chunk: {e}"))?;
            out
        }
        other => {
            return Err(format!(
                "chunks compressed with '{other}' are not supported"
            ));
        }
    };
    if out.len() != size {
        return Err(format!(
            "a chunk holds {} bytes where its header says {size}",
            out.len()
        ));
    }
    if header.uncompressed_crc != 0 && crc32fast::hash(&out) != header.uncompressed_crc {
        return Err("a chunk's CRC does not match its contents".into());
    }
    Ok(out)
}

/// The `(opcode, body)` records of a decompressed chunk (opcode u8, length
/// u64 little-endian, body), bounds-checked.
fn chunk_records(mut bytes: &[u8]) -> Result<Vec<(u8, &[u8])>, String> {
    let mut out = Vec::new();
    while !bytes.is_empty() {
        if bytes.len() < 9 {
            return Err("a record inside a chunk is cut short".into());
        }
        let op = bytes[0];
        let mut len = [0u8; 8];
        len.copy_from_slice(&bytes[1..9]);
        let len = usize::try_from(u64::from_le_bytes(len))
            .ok()
            .filter(|&l| l <= bytes.len() - 9)
            .ok_or("a record inside a chunk runs past its end")?;
        out.push((op, &bytes[9..9 + len]));
        bytes = &bytes[9 + len..];
    }
    Ok(out)
}

/// Writes small MCAP files of CDR messages (for tests and benchmarks).
pub struct McapWriter<W: std::io::Write + std::io::Seek> {
    writer: mcap::Writer<W>,
    channels: HashMap<String, u16>,
    sequence: u32,
}

impl<W: std::io::Write + std::io::Seek> McapWriter<W> {
    /// A writer whose chunks are compressed with zstd (as `ros2 bag record` does) or not at all.
    pub fn new(out: W, zstd: bool) -> Result<Self, mcap::McapError> {
        let writer = mcap::WriteOptions::new()
            .compression(zstd.then_some(mcap::Compression::Zstd))
            .profile("ros2")
            .create(out)?;
        Ok(Self {
            writer,
            channels: HashMap::new(),
            sequence: 0,
        })
    }

    /// Write a CDR message on `topic` of ROS 2 type `type_name` (`pkg/msg/Type`).
    pub fn message(
        &mut self,
        topic: &str,
        type_name: &str,
        t_ns: u64,
        data: &[u8],
    ) -> Result<(), mcap::McapError> {
        let id = match self.channels.get(topic) {
            Some(&id) => id,
            None => {
                let schema = self.writer.add_schema(type_name, "ros2msg", b"")?;
                let id = self.writer.add_channel(
                    schema,
                    topic,
                    "cdr",
                    &std::collections::BTreeMap::new(),
                )?;
                self.channels.insert(topic.to_string(), id);
                id
            }
        };
        self.sequence += 1;
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: self.sequence,
                log_time: t_ns,
                publish_time: t_ns,
            },
            data,
        )
    }

    pub fn finish(mut self) -> Result<(), mcap::McapError> {
        self.writer.finish().map(|_| ())
    }
}
