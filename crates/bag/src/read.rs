//! Reading, streamed: a file is read record by record and a chunk at a time, never whole; memory is
//! one chunk (compressed and decompressed, each at most [`RECORD_LIMIT`]) plus, for a file with a
//! summary, its channels and 24 bytes per chunk of its chunk index.
//!
//! Every chunk's `uncompressed_crc` is checked before any of its messages is given out. A chunk that
//! fails its CRC, does not decompress or is not a well-formed chunk is skipped and reported in
//! [`Recording::warnings`] with what was lost (counted from the message indexes that follow it);
//! every intact chunk is still read. A damaged record header is stepped over with the summary's
//! chunk index when the file has one.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use serde::de::DeserializeOwned;
use softcontact_msgs::RosType;

use crate::metadata::{MetadataFile, Qos};
use crate::{BagError, Result, cdr};

/// The largest record read \[bytes\]: a chunk, compressed or decompressed, or a message or schema
/// outside chunks. Writers close chunks far below it (this crate at 1 MiB, `ros2 bag` at 768 KiB).
pub const RECORD_LIMIT: u64 = 256 << 20;
/// Opcode and length prefix of every record.
const PREFIX: u64 = 9;
/// The footer record (opcode, length, 20 bytes) and the end magic.
const FOOTER_AND_MAGIC: u64 = PREFIX + 20 + 8;
const MAGIC_LEN: u64 = 8;

/// A topic of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Topic {
    pub name: String,
    /// `pkg/msg/Type`.
    pub type_name: String,
    /// The `ros2msg` definition the recording carries (empty if it has none).
    pub definition: String,
    pub message_encoding: String,
    /// The QoS its publisher offered, when recorded.
    pub qos: Option<Qos>,
    pub message_count: u64,
}

type Channels = HashMap<u16, Arc<mcap::Channel<'static>>>;

/// What a file's summary says, when it has an intact one.
struct Summary {
    channels: Channels,
    /// Chunk start offset → (record length with its prefix, first and last log time).
    chunks: BTreeMap<u64, (u64, u64, u64)>,
    stats: Option<mcap::records::Statistics>,
    /// Where the data section ends: the summary's start.
    data_end: u64,
}

struct File {
    path: PathBuf,
    size: u64,
    /// Ends with its footer and magic; else it is read up to its last complete record.
    complete: bool,
    summary: Option<Summary>,
}

impl File {
    /// Where records stop: the summary, the footer, or the end of a file without one.
    fn data_end(&self) -> u64 {
        match (&self.summary, self.complete) {
            (Some(s), _) => s.data_end,
            (None, true) => self.size - FOOTER_AND_MAGIC,
            (None, false) => self.size,
        }
    }
}

/// A ROS 2 recording opened for reading: one .mcap file or a rosbag2 folder (see the crate doc).
pub struct Recording {
    files: Vec<File>,
    topics: Vec<Topic>,
    warnings: Vec<String>,
    /// Damage found while reading (each said once, however often the recording is read).
    damage: Mutex<Vec<String>>,
    time_range: Option<(u64, u64)>,
}

/// One recorded message.
pub struct BagMessage<'a> {
    channel: Arc<mcap::Channel<'a>>,
    /// When it was received [ns since the epoch].
    pub log_time: u64,
    /// CDR, encapsulation header included.
    pub data: Cow<'a, [u8]>,
}

impl BagMessage<'_> {
    pub fn topic(&self) -> &str {
        &self.channel.topic
    }

    /// The recorded type, as the recording names it.
    pub fn type_name(&self) -> &str {
        self.channel.schema.as_ref().map_or("", |s| s.name.as_str())
    }

    /// Whether the recorded type is `T` (`pkg/msg/Type` or `pkg/Type`).
    pub fn is<T: RosType>(&self) -> bool {
        self.type_name()
            .strip_prefix(T::PACKAGE)
            .and_then(|rest| rest.strip_prefix("/msg/").or_else(|| rest.strip_prefix('/')))
            .is_some_and(|name| name == T::NAME)
    }

    /// Decodes the message as `T`; a different recorded type or a non-CDR encoding is an error.
    pub fn decode<T: RosType + DeserializeOwned>(&self) -> Result<T> {
        if !self.is::<T>() {
            return Err(BagError::WrongType {
                topic: self.topic().into(),
                found: self.type_name().into(),
                expected: T::type_path(),
            });
        }
        if self.channel.message_encoding != "cdr" {
            return Err(BagError::NotCdr {
                topic: self.topic().into(),
                encoding: self.channel.message_encoding.clone(),
            });
        }
        cdr::decode(&self.data).map_err(|message| BagError::Cdr {
            topic: self.topic().into(),
            type_name: self.type_name().into(),
            message,
        })
    }
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> BagError + '_ {
    move |source| BagError::Io { path: path.into(), error: source }
}

/// Fills `buf` as far as the input goes; the bytes read.
fn read_up_to(input: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
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

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

/// Opens one .mcap file: a regular file only (not a device, a FIFO or a folder), MCAP magic at its
/// start, its footer and summary if it was closed.
fn open_file(path: &Path, warnings: &mut Vec<String>) -> Result<File> {
    let meta = std::fs::metadata(path).map_err(io_error(path))?;
    if !meta.is_file() {
        return Err(BagError::NotAFile(path.into()));
    }
    let size = meta.len();
    if size == 0 {
        return Err(BagError::Empty(path.into()));
    }
    let mut input = std::fs::File::open(path).map_err(io_error(path))?;
    let mut magic = [0u8; MAGIC_LEN as usize];
    if read_up_to(&mut input, &mut magic).map_err(io_error(path))? < magic.len() || magic != mcap::MAGIC {
        return Err(BagError::NotMcap(path.into()));
    }
    let mut file = File { path: path.into(), size, complete: false, summary: None };
    if size < MAGIC_LEN + FOOTER_AND_MAGIC {
        return Ok(file);
    }
    let mut tail = [0u8; FOOTER_AND_MAGIC as usize];
    input.seek(SeekFrom::Start(size - FOOTER_AND_MAGIC)).map_err(io_error(path))?;
    input.read_exact(&mut tail).map_err(io_error(path))?;
    file.complete = tail[0] == op::FOOTER && u64_at(&tail, 1) == 20 && tail[29..] == *mcap::MAGIC;
    let summary_start = u64_at(&tail, 9);
    if file.complete && summary_start != 0 {
        match read_summary(&mut input, summary_start, size) {
            Ok(summary) => file.summary = Some(summary),
            Err(why) => warnings
                .push(format!("{}: its summary is damaged ({why}); the file is read through instead", path.display())),
        }
    }
    Ok(file)
}

/// The summary section, its CRC checked (mcap's linear reader checks it when it follows a data end
/// record: one is put before it).
fn read_summary(input: &mut std::fs::File, start: u64, size: u64) -> std::result::Result<Summary, String> {
    if start < MAGIC_LEN || start > size - FOOTER_AND_MAGIC {
        return Err(format!("it starts at byte {start}, outside the file"));
    }
    input.seek(SeekFrom::Start(start)).map_err(|e| e.to_string())?;
    let mut input = BufReader::new(input.take(size - start));
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(RECORD_LIMIT as usize),
    );
    let data_end = [&[op::DATA_END][..], &4u64.to_le_bytes(), &[0; 4]].concat();
    reader.insert(data_end.len()).copy_from_slice(&data_end);
    reader.notify_read(data_end.len());
    let mut schemas = HashMap::new();
    let mut channels = HashMap::new();
    let mut chunks = BTreeMap::new();
    let mut stats = None;
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| e.to_string())? {
            LinearReadEvent::ReadRequest(n) => {
                let n = n.min(1 << 20);
                let got = read_up_to(&mut input, reader.insert(n)).map_err(|e| e.to_string())?;
                reader.notify_read(got);
            }
            LinearReadEvent::Record { opcode, data } => {
                match mcap::parse_record(opcode, data).map_err(|e| e.to_string())? {
                    Record::Schema { header, data } => add_schema(&mut schemas, header, data),
                    Record::Channel(c) => add_channel(&mut channels, &schemas, c),
                    Record::ChunkIndex(c) => {
                        chunks.insert(c.chunk_start_offset, (c.chunk_length, c.message_start_time, c.message_end_time));
                    }
                    Record::Statistics(s) => stats = Some(s),
                    _ => {}
                }
            }
        }
    }
    Ok(Summary { channels, chunks, stats, data_end: start })
}

fn add_schema(schemas: &mut HashMap<u16, Arc<mcap::Schema<'static>>>, h: mcap::records::SchemaHeader, data: Cow<[u8]>) {
    let schema = mcap::Schema { id: h.id, name: h.name, encoding: h.encoding, data: Cow::Owned(data.into_owned()) };
    schemas.insert(h.id, Arc::new(schema));
}

fn add_channel(channels: &mut Channels, schemas: &HashMap<u16, Arc<mcap::Schema<'static>>>, c: mcap::records::Channel) {
    let channel = mcap::Channel {
        id: c.id,
        topic: c.topic,
        schema: schemas.get(&c.schema_id).cloned(),
        message_encoding: c.message_encoding,
        metadata: c.metadata,
    };
    channels.insert(c.id, Arc::new(channel));
}

/// A chunk (or record) skipped as damaged, waiting for the message indexes after it to say what it held.
struct Lost {
    offset: u64,
    reason: String,
    times: Option<(u64, u64)>,
    counts: BTreeMap<u16, u64>,
}

/// Reads one file's messages a record at a time (a chunk's messages are decoded together, once its
/// CRC is checked).
struct FileReader<'r> {
    file: &'r File,
    input: BufReader<std::fs::File>,
    pos: u64,
    end: u64,
    schemas: HashMap<u16, Arc<mcap::Schema<'static>>>,
    channels: Channels,
    pending: VecDeque<BagMessage<'static>>,
    lost: Option<Lost>,
    /// Messages whose channel record was lost, per channel id.
    orphans: BTreeMap<u16, u64>,
    chunks: u64,
    unverified: u64,
    /// Where and why an unclosed file's records ended.
    cut: Option<String>,
    done: bool,
    damage: &'r Mutex<Vec<String>>,
}

/// Why a file could not be read on.
enum Stop {
    Io(std::io::Error),
}

impl<'r> FileReader<'r> {
    fn new(file: &'r File, damage: &'r Mutex<Vec<String>>) -> Result<Self> {
        let mut input = std::fs::File::open(&file.path).map_err(io_error(&file.path))?;
        input.seek(SeekFrom::Start(MAGIC_LEN)).map_err(io_error(&file.path))?;
        Ok(Self {
            file,
            input: BufReader::with_capacity(1 << 16, input),
            pos: MAGIC_LEN,
            end: file.data_end(),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            pending: VecDeque::new(),
            lost: None,
            orphans: BTreeMap::new(),
            chunks: 0,
            unverified: 0,
            cut: None,
            done: false,
            damage,
        })
    }

    fn next_message(&mut self) -> Option<Result<BagMessage<'static>>> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Some(Ok(m));
            }
            if self.done {
                return None;
            }
            if let Err(Stop::Io(source)) = self.step() {
                self.finish();
                return Some(Err(BagError::Io { path: self.file.path.clone(), error: source }));
            }
        }
    }

    fn report(&self, warning: String) {
        let mut damage = self.damage.lock().unwrap_or_else(|e| e.into_inner());
        if !damage.contains(&warning) {
            damage.push(warning);
        }
    }

    fn topic_of(&self, channel: u16) -> String {
        self.channels
            .get(&channel)
            .or_else(|| self.file.summary.as_ref().and_then(|s| s.channels.get(&channel)))
            .map_or_else(|| format!("channel #{channel}"), |c| c.topic.clone())
    }

    /// Reports the damaged record waiting for its message indexes.
    fn close_lost(&mut self) {
        let Some(lost) = self.lost.take() else { return };
        let when = lost.times.map_or(String::new(), |(a, b)| {
            let t0 = self.file.summary.as_ref().and_then(|s| s.stats.as_ref()).map(|s| s.message_start_time);
            match t0 {
                Some(t0) if a >= t0 && b >= a => {
                    format!(
                        ", log times {:.3} to {:.3} s into the file",
                        (a - t0) as f64 * 1e-9,
                        (b - t0) as f64 * 1e-9
                    )
                }
                _ => format!(", log times {a} to {b} ns"),
            }
        });
        let what = if lost.counts.is_empty() {
            "its messages are lost (no message index after it to count them)".to_string()
        } else {
            let total: u64 = lost.counts.values().sum();
            let per: Vec<String> = lost.counts.iter().map(|(c, n)| format!("{} {n}", self.topic_of(*c))).collect();
            format!("{total} messages lost ({})", per.join(", "))
        };
        self.report(format!(
            "{}: damaged chunk at byte {}{when} skipped ({}): {what}; every other chunk is read",
            self.file.path.display(),
            lost.offset,
            lost.reason
        ));
    }

    fn finish(&mut self) {
        self.close_lost();
        self.done = true;
        self.pending.clear();
        if !self.orphans.is_empty() {
            let total: u64 = self.orphans.values().sum();
            let ids: Vec<String> = self.orphans.iter().map(|(c, n)| format!("#{c} {n}")).collect();
            self.report(format!(
                "{}: {total} messages skipped: their channel's record was lost with a damaged chunk ({})",
                self.file.path.display(),
                ids.join(", ")
            ));
        }
        if self.unverified > 0 {
            self.report(format!(
                "{}: {} of {} chunks carry no CRC (their writer computed none): their contents are not verified",
                self.file.path.display(),
                self.unverified,
                self.chunks
            ));
        }
    }

    fn seek_to(&mut self, pos: u64) -> Result<(), Stop> {
        self.input.seek(SeekFrom::Start(pos)).map_err(Stop::Io)?;
        self.pos = pos;
        Ok(())
    }

    /// Damage at `self.pos` that breaks the record framing: on at the next chunk the index knows,
    /// else the file ends here.
    fn resync(&mut self, reason: String, record_end: u64) -> Result<(), Stop> {
        self.close_lost();
        let at = self.pos;
        let next = self.file.summary.as_ref().and_then(|s| s.chunks.range(at + 1..).next().map(|(o, _)| *o));
        match next {
            Some(next) => {
                self.report(format!(
                    "{}: damaged record at byte {at} ({reason}); skipped to the next chunk, at byte {next}",
                    self.file.path.display()
                ));
                self.seek_to(next)
            }
            None if !self.file.complete && record_end > self.file.size => {
                // A killed writer's last record: the warning at opening says so.
                self.cut = Some(format!("a record cut at byte {at}"));
                self.finish();
                Ok(())
            }
            None => {
                self.report(format!(
                    "{}: damaged record at byte {at} ({reason}); nothing after it can be read (no chunk index to \
                     find the next chunk)",
                    self.file.path.display()
                ));
                self.finish();
                Ok(())
            }
        }
    }

    /// Reads one record.
    fn step(&mut self) -> Result<(), Stop> {
        if self.pos + PREFIX > self.end {
            if self.pos < self.end && !self.file.complete {
                self.cut = Some(format!("a record cut at byte {}", self.pos));
            }
            self.finish();
            return Ok(());
        }
        let mut prefix = [0u8; PREFIX as usize];
        self.input.read_exact(&mut prefix).map_err(Stop::Io)?;
        let (opcode, len) = (prefix[0], u64_at(&prefix, 1));
        let record_end = self.pos.saturating_add(PREFIX).saturating_add(len);
        let indexed = self.file.summary.as_ref().and_then(|s| s.chunks.get(&self.pos).copied());
        if let Some((length, first, last)) = indexed
            && (opcode != op::CHUNK || len.checked_add(PREFIX) != Some(length))
        {
            // The index says a chunk is here, of this length: its header is damaged.
            self.close_lost();
            self.lost = Some(Lost {
                offset: self.pos,
                reason: format!(
                    "its record header does not match the chunk index (opcode {opcode:#04x}, length {len})"
                ),
                times: Some((first, last)),
                counts: BTreeMap::new(),
            });
            return self.seek_to(self.pos + length);
        }
        if opcode == 0 || record_end > self.end {
            return self.resync(format!("opcode {opcode:#04x}, length {len} runs past the data section"), record_end);
        }
        if opcode != op::MESSAGE_INDEX {
            self.close_lost();
        }
        let body_limit = |len: u64| len <= RECORD_LIMIT;
        match opcode {
            op::DATA_END | op::FOOTER => {
                self.finish();
                Ok(())
            }
            op::CHUNK if body_limit(len) => self.chunk(len),
            op::SCHEMA | op::CHANNEL | op::MESSAGE | op::MESSAGE_INDEX if body_limit(len) => {
                if opcode == op::MESSAGE_INDEX && self.lost.is_none() {
                    return self.skip(len);
                }
                let mut body = vec![0u8; len as usize];
                self.input.read_exact(&mut body).map_err(Stop::Io)?;
                self.pos = record_end;
                match mcap::parse_record(opcode, &body) {
                    Ok(Record::Schema { header, data }) => add_schema(&mut self.schemas, header, data),
                    Ok(Record::Channel(c)) => add_channel(&mut self.channels, &self.schemas, c),
                    Ok(Record::Message { header, data }) => self.message(header, data.into_owned()),
                    Ok(Record::MessageIndex(index)) => {
                        if let Some(lost) = &mut self.lost {
                            *lost.counts.entry(index.channel_id).or_default() += index.records.len() as u64;
                        }
                    }
                    Ok(_) => {}
                    Err(e) => self.report(format!(
                        "{}: damaged record at byte {} skipped ({e})",
                        self.file.path.display(),
                        record_end - len - PREFIX
                    )),
                }
                Ok(())
            }
            op::CHUNK | op::SCHEMA | op::CHANNEL | op::MESSAGE => {
                self.resync(format!("opcode {opcode:#04x}, length {len} above the limit of {RECORD_LIMIT}"), record_end)
            }
            _ => self.skip(len),
        }
    }

    fn skip(&mut self, len: u64) -> Result<(), Stop> {
        let to = self.pos + PREFIX + len;
        match i64::try_from(len) {
            Ok(l) => self.input.seek_relative(l).map_err(Stop::Io)?,
            Err(_) => return self.seek_to(to),
        }
        self.pos = to;
        Ok(())
    }

    fn message(&mut self, header: mcap::records::MessageHeader, data: Vec<u8>) {
        let channel = self
            .channels
            .get(&header.channel_id)
            .or_else(|| self.file.summary.as_ref().and_then(|s| s.channels.get(&header.channel_id)));
        match channel {
            Some(channel) => {
                self.pending.push_back(BagMessage {
                    channel: channel.clone(),
                    log_time: header.log_time,
                    data: Cow::Owned(data),
                });
            }
            None => *self.orphans.entry(header.channel_id).or_default() += 1,
        }
    }

    /// A chunk record of body length `len`: its CRC checked and decompressed by mcap's linear reader,
    /// then its records applied; on any error, nothing of it.
    fn chunk(&mut self, len: u64) -> Result<(), Stop> {
        let offset = self.pos;
        self.chunks += 1;
        let mut reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_skip_start_magic(true)
                .with_skip_end_magic(true)
                .with_prevalidate_chunk_crcs(true)
                .with_record_length_limit(RECORD_LIMIT as usize),
        );
        let prefix = [&[op::CHUNK][..], &len.to_le_bytes()].concat();
        reader.insert(prefix.len()).copy_from_slice(&prefix);
        reader.notify_read(prefix.len());
        let body = reader.insert(len as usize);
        self.input.read_exact(body).map_err(Stop::Io)?;
        // message_start_time, message_end_time, uncompressed_size, uncompressed_crc
        let header = (body.len() >= 28)
            .then(|| (u64_at(body, 0), u64_at(body, 8), u32::from_le_bytes(body[24..28].try_into().expect("4 bytes"))));
        reader.notify_read(len as usize);
        self.pos += PREFIX + len;
        let mut records = Vec::new();
        let mut error = None;
        while let Some(event) = reader.next_event() {
            match event {
                Err(e) => {
                    error = Some(e.to_string());
                    break;
                }
                // Everything is in: asking for more means the chunk is cut short.
                Ok(LinearReadEvent::ReadRequest(_)) => reader.notify_read(0),
                Ok(LinearReadEvent::Record { opcode, data }) => match mcap::parse_record(opcode, data) {
                    Ok(r) => records.push(r.into_owned()),
                    Err(e) => {
                        error = Some(e.to_string());
                        break;
                    }
                },
            }
        }
        if header.is_some_and(|h| h.2 == 0) {
            self.unverified += 1;
        }
        if let Some(reason) = error {
            let reason = match reason.as_str() {
                r if r.contains("CRC") || r.contains("crc") => format!("CRC mismatch: {r}"),
                r => r.to_string(),
            };
            self.lost = Some(Lost { offset, reason, times: header.map(|h| (h.0, h.1)), counts: BTreeMap::new() });
            return Ok(());
        }
        for record in records {
            match record {
                Record::Schema { header, data } => add_schema(&mut self.schemas, header, data),
                Record::Channel(c) => add_channel(&mut self.channels, &self.schemas, c),
                Record::Message { header, data } => self.message(header, data.into_owned()),
                _ => {}
            }
        }
        Ok(())
    }
}

/// Every message of a recording in file order, read as it is asked for (see the module doc).
pub struct Messages<'r> {
    recording: &'r Recording,
    next_file: usize,
    current: Option<FileReader<'r>>,
}

impl Iterator for Messages<'_> {
    type Item = Result<BagMessage<'static>>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if self.current.is_none() {
                let file = self.recording.files.get(self.next_file)?;
                self.next_file += 1;
                match FileReader::new(file, &self.recording.damage) {
                    Ok(r) => self.current = Some(r),
                    Err(e) => return Some(Err(e)),
                }
            }
            let reader = self.current.as_mut().expect("set above");
            match reader.next_message() {
                Some(m) => return Some(m),
                None => self.current = None,
            }
        }
    }
}

impl Recording {
    /// Opens an `.mcap` file or a rosbag2 folder (its metadata.yaml lists the files; without one, every
    /// .mcap in it is read in name order, with a warning). Reads each file's summary, or reads it
    /// through when it has none (a killed writer's file).
    pub fn open(path: &Path) -> Result<Self> {
        let mut warnings = Vec::new();
        let paths = if path.is_dir() {
            match MetadataFile::read(path)? {
                Some(info) => info.relative_file_paths.iter().map(|p| path.join(p)).collect(),
                None => {
                    let mut found: Vec<PathBuf> = std::fs::read_dir(path)
                        .map_err(io_error(path))?
                        .filter_map(|e| e.ok().map(|e| e.path()))
                        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
                        .collect();
                    if found.is_empty() {
                        return Err(BagError::NotRecording(path.into()));
                    }
                    found.sort();
                    warnings.push(format!(
                        "{}: no metadata.yaml (the recorder did not finish); reading {} .mcap file(s) in it",
                        path.display(),
                        found.len()
                    ));
                    found
                }
            }
        } else {
            vec![path.to_path_buf()]
        };
        let files = paths.iter().map(|p| open_file(p, &mut warnings)).collect::<Result<Vec<_>>>()?;
        let mut recording =
            Self { files, topics: Vec::new(), warnings, damage: Mutex::new(Vec::new()), time_range: None };
        recording.index()?;
        Ok(recording)
    }

    /// Topics, message counts and the time range: from each file's summary, or by reading it through
    /// when it has none.
    fn index(&mut self) -> Result<()> {
        let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
        let mut bounds: Option<(u64, u64)> = None;
        let mut extend = |a: u64, b: u64| bounds = Some(bounds.map_or((a, b), |(x, y)| (x.min(a), y.max(b))));
        let mut warnings = Vec::new();
        for file in &self.files {
            match file.summary.as_ref().and_then(|s| s.stats.as_ref().map(|stats| (s, stats))) {
                Some((summary, stats)) => {
                    for channel in summary.channels.values() {
                        let count = stats.channel_message_counts.get(&channel.id).copied().unwrap_or(0);
                        add_topic(&mut topics, channel, count);
                    }
                    if stats.message_count > 0 {
                        extend(stats.message_start_time.min(stats.message_end_time), stats.message_end_time);
                    }
                }
                None => {
                    let mut reader = FileReader::new(file, &self.damage)?;
                    let mut count = 0u64;
                    while let Some(m) = reader.next_message() {
                        let m = m?;
                        count += 1;
                        add_topic(&mut topics, &m.channel, 1);
                        extend(m.log_time, m.log_time);
                    }
                    if !file.complete && count == 0 {
                        let reason = reader.cut.clone().unwrap_or_else(|| "no message in it".to_string());
                        return Err(BagError::Truncated { path: file.path.clone(), reason });
                    }
                    if !file.complete {
                        let why =
                            reader.cut.as_ref().map_or("it has no end".to_string(), |c| format!("it ends in {c}"));
                        warnings.push(format!(
                            "{}: not closed by its writer ({why}); recovered {count} messages, everything up to its \
                             last complete chunk",
                            file.path.display()
                        ));
                    }
                }
            }
        }
        self.warnings.extend(warnings);
        self.topics = topics.into_values().collect();
        self.time_range = bounds;
        Ok(())
    }

    pub fn topics(&self) -> &[Topic] {
        &self.topics
    }

    pub fn topic(&self, name: &str) -> Option<&Topic> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// What was recovered rather than read whole: a killed writer, a folder without metadata, and
    /// every damaged chunk found so far (at opening, or since, by [`Self::messages`]).
    pub fn warnings(&self) -> Vec<String> {
        let damage = self.damage.lock().unwrap_or_else(|e| e.into_inner());
        self.warnings.iter().chain(damage.iter()).cloned().collect()
    }

    pub fn message_count(&self) -> u64 {
        self.topics.iter().map(|t| t.message_count).sum()
    }

    /// First and last log time [ns since the epoch], as the summaries say (or as read).
    pub fn time_range(&self) -> Option<(u64, u64)> {
        self.time_range
    }

    /// The recording's size on disk.
    pub fn bytes(&self) -> u64 {
        self.files.iter().map(|f| f.size).sum()
    }

    /// Every message in file order (the order they were written), read from disk as the iterator
    /// goes: a chunk at a time, each chunk's CRC checked first. Damaged chunks are skipped and added to
    /// [`Self::warnings`]; a recovered file's messages end at its damage.
    pub fn messages(&self) -> Messages<'_> {
        Messages { recording: self, next_file: 0, current: None }
    }
}

fn add_topic(topics: &mut BTreeMap<String, Topic>, channel: &mcap::Channel<'_>, count: u64) {
    topics
        .entry(channel.topic.clone())
        .or_insert_with(|| Topic {
            name: channel.topic.clone(),
            type_name: channel.schema.as_ref().map_or(String::new(), |s| crate::type_path(&s.name)),
            definition: channel
                .schema
                .as_ref()
                .map_or(String::new(), |s| String::from_utf8_lossy(&s.data).into_owned()),
            message_encoding: channel.message_encoding.clone(),
            qos: channel.metadata.get("offered_qos_profiles").and_then(|q| Qos::from_yaml(q)),
            message_count: 0,
        })
        .message_count += count;
}
