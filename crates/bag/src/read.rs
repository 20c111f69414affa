use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use enumset::EnumSet;
use mcap::read::{MessageStream, Options, Summary};
use serde::de::DeserializeOwned;
use softcontact_msgs::RosType;

use crate::metadata::{MetadataFile, Qos};
use crate::{BagError, Result, cdr};

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

struct File {
    path: PathBuf,
    bytes: Vec<u8>,
    /// Ends with its footer and magic; else read up to the first damaged record.
    complete: bool,
}

/// A ROS 2 recording opened for reading: one .mcap file or a rosbag2 folder (see the crate doc).
pub struct Recording {
    files: Vec<File>,
    topics: Vec<Topic>,
    warnings: Vec<String>,
    time_range: Option<(u64, u64)>,
}

/// One recorded message, borrowed from the recording.
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

fn read_file(path: &Path) -> Result<File> {
    let bytes = std::fs::read(path).map_err(|source| BagError::Io { path: path.into(), source })?;
    if bytes.is_empty() {
        return Err(BagError::Empty(path.into()));
    }
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(BagError::NotMcap(path.into()));
    }
    let complete =
        bytes.len() >= 2 * mcap::MAGIC.len() && bytes.ends_with(mcap::MAGIC) && mcap::read::footer(&bytes).is_ok();
    Ok(File { path: path.into(), bytes, complete })
}

fn options(file: &File) -> EnumSet<Options> {
    if file.complete { EnumSet::empty() } else { EnumSet::only(Options::IgnoreEndMagic) }
}

impl Recording {
    /// Opens an `.mcap` file or a rosbag2 folder (its metadata.yaml lists the files; without one, every
    /// .mcap in it is read in name order, with a warning).
    pub fn open(path: &Path) -> Result<Self> {
        let mut warnings = Vec::new();
        let paths = if path.is_dir() {
            match MetadataFile::read(path)? {
                Some(info) => info.relative_file_paths.iter().map(|p| path.join(p)).collect(),
                None => {
                    let mut found: Vec<PathBuf> = std::fs::read_dir(path)
                        .map_err(|source| BagError::Io { path: path.into(), source })?
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
        let files = paths.iter().map(|p| read_file(p)).collect::<Result<Vec<_>>>()?;
        let mut recording = Self { files, topics: Vec::new(), warnings, time_range: None };
        recording.index()?;
        Ok(recording)
    }

    /// Topics, message counts and the time range: from each file's summary, or by reading it through
    /// when it has none (a recovered file).
    fn index(&mut self) -> Result<()> {
        let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
        let mut bounds: Option<(u64, u64)> = None;
        let mut extend = |a: u64, b: u64| bounds = Some(bounds.map_or((a, b), |(x, y)| (x.min(a), y.max(b))));
        for file in &self.files {
            let summary = if file.complete {
                Summary::read(&file.bytes).map_err(|source| BagError::Mcap { path: file.path.clone(), source })?
            } else {
                None
            };
            match summary.as_ref().and_then(|s| s.stats.as_ref().map(|stats| (s, stats))) {
                Some((summary, stats)) => {
                    for channel in summary.channels.values() {
                        let count = stats.channel_message_counts.get(&channel.id).copied().unwrap_or(0);
                        add_topic(&mut topics, channel, count);
                    }
                    if stats.message_count > 0 {
                        extend(stats.message_start_time, stats.message_end_time);
                    }
                }
                None => {
                    let mut count = 0u64;
                    let mut damaged = None;
                    for message in MessageStream::new_with_options(&file.bytes, options(file))
                        .map_err(|source| BagError::Mcap { path: file.path.clone(), source })?
                    {
                        match message {
                            Ok(m) => {
                                count += 1;
                                add_topic(&mut topics, &m.channel, 1);
                                extend(m.log_time, m.log_time);
                            }
                            Err(e) if !file.complete => {
                                damaged = Some(e);
                                break;
                            }
                            Err(source) => return Err(BagError::Mcap { path: file.path.clone(), source }),
                        }
                    }
                    if !file.complete && count == 0 {
                        let reason = damaged.map_or("no message in it".to_string(), |e| e.to_string());
                        return Err(BagError::Truncated { path: file.path.clone(), reason });
                    }
                    if !file.complete {
                        let why =
                            damaged.map_or("it has no end".to_string(), |e| format!("it ends in a broken record: {e}"));
                        self.warnings.push(format!(
                            "{}: not closed by its writer ({why}); recovered {count} messages, everything up to its \
                             last complete chunk",
                            file.path.display()
                        ));
                    }
                }
            }
        }
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

    /// What was recovered rather than read whole (a killed writer, a folder without metadata).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    pub fn message_count(&self) -> u64 {
        self.topics.iter().map(|t| t.message_count).sum()
    }

    /// First and last log time [ns since the epoch].
    pub fn time_range(&self) -> Option<(u64, u64)> {
        self.time_range
    }

    /// The recording's size on disk.
    pub fn bytes(&self) -> u64 {
        self.files.iter().map(|f| f.bytes.len() as u64).sum()
    }

    /// Every message in file order (the order they were written). A recovered file's messages end
    /// at its damage, silently: [`Self::warnings`] said so at opening.
    pub fn messages(&self) -> impl Iterator<Item = Result<BagMessage<'_>>> {
        self.files.iter().flat_map(|file| {
            let stream = MessageStream::new_with_options(&file.bytes, options(file))
                .map_err(|source| BagError::Mcap { path: file.path.clone(), source });
            let (stream, error) = match stream {
                Ok(s) => (Some(s), None),
                Err(e) => (None, Some(Err(e))),
            };
            let mut stopped = false;
            error.into_iter().chain(stream.into_iter().flatten().map_while(move |m| {
                if stopped {
                    return None;
                }
                match m {
                    Ok(m) => Some(Ok(BagMessage { channel: m.channel, log_time: m.log_time, data: m.data })),
                    Err(_) if !file.complete => None,
                    Err(source) => {
                        stopped = true;
                        Some(Err(BagError::Mcap { path: file.path.clone(), source }))
                    }
                }
            }))
        })
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
