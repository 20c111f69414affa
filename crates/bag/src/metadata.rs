//! What rosbag2 keeps beside the messages: each topic's offered QoS (channel metadata
//! `offered_qos_profiles`) and a folder's `metadata.yaml`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{BagError, Result};

/// The QoS a topic's publisher offered: what `replay` offers again, and what a rosbag2 reader expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    pub reliable: bool,
    /// Late joiners get the last `depth` samples (/tf_static).
    pub transient_local: bool,
    pub depth: u32,
}

impl Qos {
    pub const SENSOR: Qos = Qos { reliable: false, transient_local: false, depth: 1 };
    pub const RELIABLE: Qos = Qos { reliable: true, transient_local: false, depth: 10 };
    pub const LATCHED: Qos = Qos { reliable: true, transient_local: true, depth: 1 };

    /// The profile a publisher of this delivery offers.
    pub fn of(delivery: softcontact_msgs::topics::Delivery) -> Qos {
        use softcontact_msgs::topics::Delivery;
        match delivery {
            Delivery::Sensor => Qos::SENSOR,
            Delivery::Reliable => Qos::RELIABLE,
            Delivery::Latched => Qos::LATCHED,
        }
    }

    /// rosbag2's (Jazzy) YAML list of profiles, as a string.
    pub fn to_yaml(&self) -> String {
        let infinite = "\n    sec: 2147483647\n    nsec: 4294967295";
        format!(
            "- history: keep_last\n  depth: {}\n  reliability: {}\n  durability: {}\n  deadline:{infinite}\n  \
             lifespan:{infinite}\n  liveliness: automatic\n  liveliness_lease_duration:{infinite}\n  \
             avoid_ros_namespace_conventions: false\n",
            self.depth,
            if self.reliable { "reliable" } else { "best_effort" },
            if self.transient_local { "transient_local" } else { "volatile" },
        )
    }

    /// The first profile of a rosbag2 `offered_qos_profiles` string (names or Humble's numbers).
    pub fn from_yaml(text: &str) -> Option<Qos> {
        let list: Vec<serde_yaml_ng::Value> = serde_yaml_ng::from_str(text).ok()?;
        let first = list.first()?;
        let is = |key: &str, name: &str, number: u64| match &first[key] {
            serde_yaml_ng::Value::String(s) => s.eq_ignore_ascii_case(name),
            serde_yaml_ng::Value::Number(n) => n.as_u64() == Some(number),
            _ => false,
        };
        Some(Qos {
            reliable: is("reliability", "reliable", 1),
            transient_local: is("durability", "transient_local", 1),
            depth: first["depth"].as_u64().map_or(1, |d| d.clamp(1, 1000) as u32),
        })
    }
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct MetadataFile {
    pub rosbag2_bagfile_information: BagInfo,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct BagInfo {
    pub version: u32,
    pub storage_identifier: String,
    pub duration: Nanoseconds,
    pub starting_time: NanosecondsSinceEpoch,
    pub message_count: u64,
    pub topics_with_message_count: Vec<TopicWithCount>,
    #[serde(default)]
    pub compression_format: String,
    #[serde(default)]
    pub compression_mode: String,
    pub relative_file_paths: Vec<String>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub files: Vec<serde_yaml_ng::Value>,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct Nanoseconds {
    pub nanoseconds: u64,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct NanosecondsSinceEpoch {
    pub nanoseconds_since_epoch: u64,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct TopicWithCount {
    pub topic_metadata: TopicMetadata,
    pub message_count: u64,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct TopicMetadata {
    pub name: String,
    #[serde(rename = "type")]
    pub type_name: String,
    pub serialization_format: String,
    #[serde(default)]
    pub offered_qos_profiles: serde_yaml_ng::Value,
    #[serde(default)]
    pub type_description_hash: String,
}

impl MetadataFile {
    pub(crate) fn read(folder: &Path) -> Result<Option<BagInfo>> {
        let path = folder.join("metadata.yaml");
        let text = match std::fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(BagError::Io { path, error: source }),
        };
        let file: MetadataFile = serde_yaml_ng::from_str(&text)
            .map_err(|e| BagError::Metadata { path: path.clone(), message: format!("not rosbag2 metadata: {e}") })?;
        let info = file.rosbag2_bagfile_information;
        if info.storage_identifier != "mcap" {
            return Err(BagError::Metadata {
                path,
                message: format!(
                    "storage `{}`: only MCAP recordings are read (`ros2 bag convert` turns others into MCAP)",
                    info.storage_identifier
                ),
            });
        }
        if !info.compression_mode.is_empty() && !info.compression_mode.eq_ignore_ascii_case("none") {
            return Err(BagError::Metadata {
                path,
                message: format!("whole-file compression `{}` is not read; decompress first", info.compression_mode),
            });
        }
        Ok(Some(info))
    }

    pub(crate) fn write(folder: &Path, info: BagInfo) -> Result<()> {
        let path: PathBuf = folder.join("metadata.yaml");
        let text = serde_yaml_ng::to_string(&MetadataFile { rosbag2_bagfile_information: info })
            .map_err(|e| BagError::Invalid(format!("metadata.yaml: {e}")))?;
        std::fs::write(&path, text).map_err(|source| BagError::Io { path, error: source })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qos_round_trips_through_rosbag2_yaml() {
        for qos in [Qos::SENSOR, Qos::RELIABLE, Qos::LATCHED] {
            assert_eq!(Qos::from_yaml(&qos.to_yaml()), Some(qos));
        }
    }

    #[test]
    fn humble_numbers_are_understood() {
        let humble = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n";
        assert_eq!(Qos::from_yaml(humble), Some(Qos { reliable: true, transient_local: true, depth: 1 }));
        assert_eq!(Qos::from_yaml("not: [a list"), None);
    }
}
