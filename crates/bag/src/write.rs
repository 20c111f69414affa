use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;
use serde::Serialize;
use softcontact_msgs::RosType;

use crate::metadata::{BagInfo, MetadataFile, Nanoseconds, NanosecondsSinceEpoch, Qos, TopicMetadata, TopicWithCount};
use crate::{BagError, Result, cdr};

/// Chunks close at this uncompressed size (and at every [`BagWriter::flush`]).
const CHUNK_SIZE: u64 = 1 << 20;

struct Channel {
    id: u16,
    topic: String,
    type_name: String,
    qos: Qos,
    count: u64,
}

/// What a finished recording holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteStats {
    pub messages: u64,
    pub bytes: u64,
}

/// Writes a ROS 2 MCAP recording (see the crate doc).
pub struct BagWriter {
    mcap: mcap::Writer<BufWriter<File>>,
    file: PathBuf,
    /// The rosbag2 folder, when writing one.
    folder: Option<PathBuf>,
    channels: Vec<Channel>,
    sequence: u32,
    time_bounds: Option<(u64, u64)>,
    buffer: Vec<u8>,
}

impl BagWriter {
    /// A path ending in `.mcap` is one file; anything else becomes a rosbag2 folder, as `ros2 bag record
    /// -o NAME` makes. An existing file or folder is never overwritten.
    pub fn create(path: &Path) -> Result<Self> {
        let (file, folder) = if path.extension().is_some_and(|e| e == "mcap") {
            (path.to_path_buf(), None)
        } else {
            std::fs::create_dir(path).map_err(|source| BagError::Io { path: path.into(), error: source })?;
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("recording");
            (path.join(format!("{name}_0.mcap")), Some(path.to_path_buf()))
        };
        let handle = File::options()
            .write(true)
            .create_new(true)
            .open(&file)
            .map_err(|source| BagError::Io { path: file.clone(), error: source })?;
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("softcontact-bag ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(CHUNK_SIZE))
            .create(BufWriter::with_capacity(1 << 16, handle))?;
        Ok(Self { mcap, file, folder, channels: Vec::new(), sequence: 0, time_bounds: None, buffer: Vec::new() })
    }

    /// The `.mcap` file being written.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// Adds a topic of a type the project knows; returns its channel for [`Self::write`].
    /// Adds one of the graph's topics (`softcontact_msgs::topics`), with the QoS its publisher offers.
    pub fn add<T: RosType>(&mut self, topic: &softcontact_msgs::topics::Topic<T>) -> Result<u16> {
        self.add_topic::<T>(topic.name, Qos::of(topic.delivery))
    }

    pub fn add_topic<T: RosType>(&mut self, topic: &str, qos: Qos) -> Result<u16> {
        self.add_topic_with_definition(topic, &T::type_path(), T::definition(), qos)
    }

    /// Adds a topic of any type, given its full `ros2msg` definition.
    pub fn add_topic_with_definition(
        &mut self,
        topic: &str,
        type_name: &str,
        definition: &str,
        qos: Qos,
    ) -> Result<u16> {
        let type_name = crate::type_path(type_name);
        if let Some(c) = self.channels.iter().find(|c| c.topic == topic) {
            return if c.type_name == type_name {
                Ok(c.id)
            } else {
                Err(BagError::Invalid(format!("topic {topic} already recorded as {}", c.type_name)))
            };
        }
        let schema = self.mcap.add_schema(&type_name, "ros2msg", definition.as_bytes())?;
        let metadata = BTreeMap::from([("offered_qos_profiles".to_string(), qos.to_yaml())]);
        let id = self.mcap.add_channel(schema, topic, "cdr", &metadata)?;
        self.channels.push(Channel { id, topic: topic.into(), type_name, qos, count: 0 });
        Ok(id)
    }

    /// Writes one message received at `log_time` [ns since the epoch].
    pub fn write<T: Serialize>(&mut self, channel: u16, log_time: u64, msg: &T) -> Result<()> {
        let mut buffer = std::mem::take(&mut self.buffer);
        let encoded = cdr::encode_into(msg, &mut buffer);
        let result = match encoded {
            Ok(()) => self.write_cdr(channel, log_time, &buffer),
            Err(message) => {
                let c = self.channel(channel)?;
                Err(BagError::Cdr { topic: c.topic.clone(), type_name: c.type_name.clone(), message })
            }
        };
        self.buffer = buffer;
        result
    }

    /// Writes one message already in CDR (encapsulation header included).
    pub fn write_cdr(&mut self, channel: u16, log_time: u64, data: &[u8]) -> Result<()> {
        let index = self.channels.iter().position(|c| c.id == channel);
        let c = index.map(|i| &mut self.channels[i]).ok_or_else(|| BagError::UnknownTopic(format!("#{channel}")))?;
        c.count += 1;
        self.sequence = self.sequence.wrapping_add(1);
        let header = MessageHeader { channel_id: channel, sequence: self.sequence, log_time, publish_time: log_time };
        self.mcap.write_to_known_channel(&header, data)?;
        self.time_bounds = Some(match self.time_bounds {
            None => (log_time, log_time),
            Some((a, b)) => (a.min(log_time), b.max(log_time)),
        });
        Ok(())
    }

    /// Closes the chunk in progress and hands everything to the OS: a writer killed after this loses
    /// nothing written before it. Recorders call it about once a second.
    pub fn flush(&mut self) -> Result<()> {
        Ok(self.mcap.flush()?)
    }

    /// Messages written so far, per topic.
    pub fn counts(&self) -> impl Iterator<Item = (&str, u64)> {
        self.channels.iter().map(|c| (c.topic.as_str(), c.count))
    }

    /// Writes the indexes and the summary (and a folder's metadata.yaml).
    pub fn finish(mut self) -> Result<WriteStats> {
        self.mcap.finish()?;
        let messages = self.channels.iter().map(|c| c.count).sum();
        let bytes =
            std::fs::metadata(&self.file).map_err(|source| BagError::Io { path: self.file.clone(), error: source })?;
        if let Some(folder) = &self.folder {
            let (start, end) = self.time_bounds.unwrap_or((0, 0));
            let name = self.file.file_name().and_then(|n| n.to_str()).unwrap_or_default().to_string();
            let info = BagInfo {
                version: 9,
                storage_identifier: "mcap".into(),
                duration: Nanoseconds { nanoseconds: end - start },
                starting_time: NanosecondsSinceEpoch { nanoseconds_since_epoch: start },
                message_count: messages,
                topics_with_message_count: self
                    .channels
                    .iter()
                    .map(|c| TopicWithCount {
                        topic_metadata: TopicMetadata {
                            name: c.topic.clone(),
                            type_name: c.type_name.clone(),
                            serialization_format: "cdr".into(),
                            offered_qos_profiles: serde_yaml_ng::Value::String(c.qos.to_yaml()),
                            type_description_hash: String::new(),
                        },
                        message_count: c.count,
                    })
                    .collect(),
                compression_format: String::new(),
                compression_mode: String::new(),
                relative_file_paths: vec![name],
                files: Vec::new(),
            };
            MetadataFile::write(folder, info)?;
        }
        Ok(WriteStats { messages, bytes: bytes.len() })
    }

    fn channel(&self, id: u16) -> Result<&Channel> {
        self.channels.iter().find(|c| c.id == id).ok_or_else(|| BagError::UnknownTopic(format!("#{id}")))
    }
}
