//! Every message type through a file and a rosbag2 folder; damaged and foreign input.

mod common;

use std::io::Write;

use common::{T0, samples, write_samples};
use softcontact_bag::{AnyMessage, BagError, Qos, Recording};
use softcontact_msgs::RosType;
use softcontact_msgs::geometry_msgs::{PoseStamped, WrenchStamped};

fn read_all(recording: &Recording) -> Vec<(String, u64, AnyMessage)> {
    recording
        .messages()
        .map(|m| {
            let m = m.unwrap();
            (m.topic().to_string(), m.log_time, AnyMessage::decode(&m).unwrap().expect("a known type"))
        })
        .collect()
}

#[test]
fn every_message_type_round_trips_through_a_file_and_a_folder() {
    let dir = tempfile::tempdir().unwrap();
    for path in [dir.path().join("run.mcap"), dir.path().join("run_folder")] {
        let written = write_samples(&path, 50);
        let recording = Recording::open(&path).unwrap();
        assert!(recording.warnings().is_empty(), "{:?}", recording.warnings());
        assert_eq!(read_all(&recording), written);
        assert_eq!(recording.message_count(), written.len() as u64);
        assert_eq!(recording.time_range(), Some((T0, T0 + 49_000_000)));
        let names: Vec<&str> = recording.topics().iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names.len(), samples(0).len());
        let wrench = recording.topic("/ft_sensor/wrench").unwrap();
        assert_eq!(wrench.type_name, "geometry_msgs/msg/WrenchStamped");
        assert_eq!(wrench.definition, WrenchStamped::definition());
        assert_eq!(wrench.message_encoding, "cdr");
        assert_eq!(wrench.qos, Some(Qos::SENSOR));
        assert_eq!(wrench.message_count, 50);
        assert_eq!(recording.topic("/tf_static").unwrap().qos, Some(Qos::LATCHED));
    }
    let metadata = std::fs::read_to_string(dir.path().join("run_folder/metadata.yaml")).unwrap();
    assert!(metadata.contains("storage_identifier: mcap") && metadata.contains("run_folder_0.mcap"), "{metadata}");
}

#[test]
fn the_file_is_ros2_mcap_with_chunks_zstd_and_a_summary() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    write_samples(&path, 2000);
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::read::Summary::read(&bytes).unwrap().expect("a summary");
    assert!(summary.chunk_indexes.len() >= 2, "{} chunks", summary.chunk_indexes.len());
    assert!(summary.chunk_indexes.iter().all(|c| c.compression == "zstd" && !c.message_index_offsets.is_empty()));
    assert!(summary.schemas.values().all(|s| s.encoding == "ros2msg" && s.name.contains("/msg/")));
    assert!(summary.channels.values().all(|c| c.message_encoding == "cdr"));
    let header = mcap::read::LinearReader::new(&bytes).unwrap().next().unwrap().unwrap();
    assert!(matches!(header, mcap::records::Record::Header(h) if h.profile == "ros2"));
}

#[test]
fn a_message_read_as_another_type_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    write_samples(&path, 1);
    let recording = Recording::open(&path).unwrap();
    let m = recording.messages().map(Result::unwrap).find(|m| m.topic() == "/ft_sensor/wrench").unwrap();
    let err = m.decode::<PoseStamped>().unwrap_err();
    assert!(matches!(err, BagError::WrongType { .. }));
    assert_eq!(
        err.to_string(),
        "topic /ft_sensor/wrench: recorded as geometry_msgs/msg/WrenchStamped, read as geometry_msgs/msg/PoseStamped"
    );
}

#[test]
fn truncation_anywhere_recovers_every_complete_chunk_or_says_nothing_is_left() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let written = write_samples(&path, 3000);
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::read::Summary::read(&bytes).unwrap().unwrap();
    let chunk_ends: Vec<u64> = summary.chunk_indexes.iter().map(|c| c.chunk_start_offset + c.chunk_length).collect();
    let cut_path = dir.path().join("cut.mcap");
    for cut in (9..bytes.len() - 1).step_by(bytes.len() / 97) {
        std::fs::write(&cut_path, &bytes[..cut]).unwrap();
        let complete_chunks = chunk_ends.iter().filter(|&&end| end <= cut as u64).count();
        match Recording::open(&cut_path) {
            Ok(recording) => {
                assert_eq!(recording.warnings().len(), 1, "cut at {cut}");
                assert!(recording.warnings()[0].contains("not closed by its writer"));
                let read = read_all(&recording);
                // Every message of the complete chunks (and what decompresses of the cut one), in order,
                // values intact.
                assert_eq!(read[..], written[..read.len()], "cut at {cut}");
                let wanted = summary.chunk_indexes[..complete_chunks]
                    .last()
                    .map_or(0, |c| written.iter().filter(|w| w.1 < c.message_end_time).count() as u64);
                assert!(read.len() as u64 >= wanted, "cut at {cut}: {} of {wanted}", read.len());
            }
            Err(e) => {
                assert_eq!(complete_chunks, 0, "cut at {cut}: {e}");
                assert!(matches!(e, BagError::Truncated { .. }), "cut at {cut}: {e}");
            }
        }
    }
}

#[test]
fn empty_foreign_and_missing_input_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.mcap");
    std::fs::File::create(&empty).unwrap();
    assert!(matches!(Recording::open(&empty), Err(BagError::Empty(_))));
    let text = dir.path().join("notes.mcap");
    std::fs::File::create(&text).unwrap().write_all(b"k: 25000\nlambda: 1100\n").unwrap();
    let err = Recording::open(&text).err().unwrap();
    assert!(err.to_string().ends_with("not an MCAP file (no MCAP magic at its start)"), "{err}");
    assert!(matches!(Recording::open(&dir.path().join("absent.mcap")), Err(BagError::Io { .. })));
    let folder = dir.path().join("no_bag");
    std::fs::create_dir(&folder).unwrap();
    assert!(matches!(Recording::open(&folder), Err(BagError::NotRecording(_))));
    std::fs::write(
        folder.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n  duration: {nanoseconds: 0}\n  \
         starting_time: {nanoseconds_since_epoch: 0}\n  message_count: 0\n  topics_with_message_count: []\n  \
         relative_file_paths: [no_bag_0.db3]\n",
    )
    .unwrap();
    let err = Recording::open(&folder).err().unwrap();
    assert!(err.to_string().contains("storage `sqlite3`"), "{err}");
}

#[test]
fn a_folder_whose_writer_never_wrote_metadata_is_read_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("run");
    let written = write_samples(&folder, 10);
    std::fs::remove_file(folder.join("metadata.yaml")).unwrap();
    let recording = Recording::open(&folder).unwrap();
    assert_eq!(recording.warnings().len(), 1);
    assert_eq!(read_all(&recording), written);
}
