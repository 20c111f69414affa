//! Damaged recordings: every chunk's CRC is checked; a damaged chunk is skipped and reported with what it
//! held, every intact chunk is still read, value for value.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::{T0, qos_of, samples};
use softcontact_bag::{AnyMessage, BagWriter, Recording};
use softcontact_msgs::sensor_msgs::JointState;

type Written = Vec<(String, u64, AnyMessage)>;

/// `rounds` rounds of every sample, 1 ms apart, a chunk closed every `per_chunk` rounds.
fn write_chunked(path: &Path, rounds: u32, per_chunk: u32) -> Written {
    let mut writer = BagWriter::create(path).unwrap();
    let mut written = Vec::new();
    for i in 0..rounds {
        let t = T0 + i as u64 * 1_000_000;
        for (topic, msg) in samples(i) {
            msg.write(&mut writer, topic, qos_of(topic), t).unwrap();
            written.push((topic.to_string(), t, msg));
        }
        if i % per_chunk == per_chunk - 1 {
            writer.flush().unwrap();
        }
    }
    writer.finish().unwrap();
    written
}

/// Every message read, and whether reading ended in an error.
fn read_all(recording: &Recording) -> (Written, Option<String>) {
    let mut read = Vec::new();
    for m in recording.messages() {
        match m {
            Ok(m) => read.push((m.topic().to_string(), m.log_time, AnyMessage::decode(&m).unwrap().unwrap())),
            Err(e) => return (read, Some(e.to_string())),
        }
    }
    (read, None)
}

struct Chunk {
    start: u64,
    length: u64,
    /// Where its compressed records start, and how many bytes they are.
    data: u64,
    data_len: u64,
    times: (u64, u64),
}

fn chunks(bytes: &[u8]) -> Vec<Chunk> {
    let summary = mcap::read::Summary::read(bytes).unwrap().unwrap();
    summary
        .chunk_indexes
        .iter()
        .map(|c| Chunk {
            start: c.chunk_start_offset,
            length: c.chunk_length,
            // prefix 9, then start/end time, uncompressed size, CRC, compression string, compressed size
            data: c.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + c.compression.len() as u64 + 8,
            data_len: c.compressed_size,
            times: (c.message_start_time, c.message_end_time),
        })
        .collect()
}

fn without(written: &Written, times: (u64, u64)) -> Written {
    written.iter().filter(|w| w.1 < times.0 || w.1 > times.1).cloned().collect()
}

fn flipped(bytes: &[u8], at: u64, path: &Path) {
    let mut bytes = bytes.to_vec();
    bytes[at as usize] ^= 0x10;
    std::fs::write(path, bytes).unwrap();
}

/// A recording of `rounds` rounds, a chunk every 100, in a fresh folder (kept while the `TempDir` lives):
/// the messages written, the file's bytes and its chunks.
fn recorded(rounds: u32) -> (tempfile::TempDir, Written, Vec<u8>, Vec<Chunk>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let written = write_chunked(&path, rounds, 100);
    let bytes = std::fs::read(&path).unwrap();
    let chunks = chunks(&bytes);
    (dir, written, bytes, chunks)
}

/// `bytes` with the byte at `at` flipped, written to `path` and opened: the recording and every message
/// read, which must end without an error (`what` says which flip in the message if not).
fn read_flipped(bytes: &[u8], at: u64, path: &Path, what: &str) -> (Recording, Written) {
    flipped(bytes, at, path);
    let recording = Recording::open(path).unwrap();
    let (read, error) = read_all(&recording);
    assert_eq!(error, None, "{what}");
    (recording, read)
}

#[test]
fn a_flipped_byte_in_a_zstd_chunk_loses_that_chunk_only_with_a_warning_that_counts_it() {
    let (dir, written, bytes, chunks) = recorded(600);
    assert!(chunks.len() >= 6, "{} chunks", chunks.len());
    let damaged = dir.path().join("damaged.mcap");
    for (k, chunk) in chunks.iter().enumerate() {
        let (recording, read) = read_flipped(&bytes, chunk.data + chunk.data_len / 2, &damaged, &format!("chunk {k}"));
        let want = without(&written, chunk.times);
        let lost = written.len() - want.len();
        assert_eq!(lost, 100 * samples(0).len(), "chunk {k} holds 100 rounds");
        assert!(read == want, "chunk {k}: {} messages read, {} wanted, values intact", read.len(), want.len());
        let warnings = recording.warnings();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        let w = &warnings[0];
        assert!(w.contains(&format!("damaged chunk at byte {}", chunk.start)), "{w}");
        assert!(w.contains(&format!("{lost} messages lost (")) && w.contains("/ft_sensor/wrench 100"), "{w}");
        assert!(w.contains("every other chunk is read"), "{w}");
    }
}

#[test]
fn any_flipped_byte_of_a_chunk_record_loses_at_most_that_chunk_never_a_changed_value() {
    let (dir, written, bytes, chunks) = recorded(500);
    let chunk = &chunks[2];
    let want = without(&written, chunk.times);
    let damaged = dir.path().join("damaged.mcap");
    // The prefix and header byte by byte, then 150 bytes spread over the compressed data.
    let header: Vec<u64> = (chunk.start..chunk.data).collect();
    let data = (0..150).map(|i| chunk.data + i * (chunk.length - (chunk.data - chunk.start)) / 150);
    let (mut whole, mut lost) = (0, 0);
    for at in header.into_iter().chain(data) {
        let (recording, read) = read_flipped(&bytes, at, &damaged, &format!("byte {at}"));
        if read == written {
            // In the header, only a field the reader does not need (a time bound) may be hit so; in the
            // compressed data, a byte the decoder does not read back (every value is still intact).
            whole += usize::from(at < chunk.data);
        } else {
            assert!(read == want, "byte {at}: {} messages read, {} wanted", read.len(), want.len());
            assert!(recording.warnings().iter().any(|w| w.contains("damaged")), "byte {at}");
            lost += 1;
        }
    }
    assert!(lost > 150 && whole <= 16, "{lost} flips lost the chunk, {whole} in the header were harmless");
}

/// A ROS 2 file of uncompressed chunks of torque commands, as another writer may make it.
fn write_uncompressed(path: &Path) -> Vec<JointState> {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut writer = mcap::WriteOptions::new().profile("ros2").compression(None).create(file).unwrap();
    let schema = writer
        .add_schema(
            "sensor_msgs/msg/JointState",
            "ros2msg",
            softcontact_msgs::definition("sensor_msgs/msg/JointState").unwrap().as_bytes(),
        )
        .unwrap();
    let channel = writer.add_channel(schema, "/lwr/joint_torque_command", "cdr", &BTreeMap::new()).unwrap();
    let mut sent = Vec::new();
    for i in 0..40u32 {
        let msg = JointState { effort: vec![1.25 + i as f64; 7], ..Default::default() };
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: i,
            log_time: T0 + i as u64 * 1_000_000,
            publish_time: T0 + i as u64 * 1_000_000,
        };
        writer.write_to_known_channel(&header, &softcontact_bag::cdr::encode(&msg).unwrap()).unwrap();
        sent.push(msg);
        if i % 10 == 9 {
            writer.flush().unwrap();
        }
    }
    writer.finish().unwrap();
    sent
}

#[test]
fn a_flipped_byte_in_an_uncompressed_chunk_is_caught_by_its_crc_not_replayed_as_a_changed_torque() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.mcap");
    let sent = write_uncompressed(&path);
    let bytes = std::fs::read(&path).unwrap();
    assert!(chunks(&bytes).len() == 4);
    // The torque 26.25 Nm of message 25 (third chunk): flip a bit of its mantissa. It still decodes,
    // as another torque.
    let needle = 26.25f64.to_le_bytes();
    let at = bytes.windows(8).position(|w| w == needle).unwrap() as u64;
    let damaged = dir.path().join("damaged.mcap");
    flipped(&bytes, at + 1, &damaged);
    let recording = Recording::open(&damaged).unwrap();
    let read: Vec<JointState> = recording.messages().map(|m| m.unwrap().decode::<JointState>().unwrap()).collect();
    let want: Vec<JointState> = sent.iter().filter(|m| !(21.25..31.0).contains(&m.effort[0])).cloned().collect();
    assert_eq!(read, want, "the third chunk (torques 21.25..30.25) is skipped, the others are intact");
    let warnings = recording.warnings();
    assert!(
        warnings.len() == 1 && warnings[0].contains("CRC mismatch") && warnings[0].contains("10 messages lost"),
        "{warnings:?}"
    );
}

#[test]
fn a_damaged_record_header_is_stepped_over_with_the_chunk_index() {
    let (dir, written, bytes, chunks) = recorded(400);
    // The opcode of the second chunk becomes 0, then its length runs past the end of the file.
    let damaged = dir.path().join("damaged.mcap");
    let mut copy = bytes.clone();
    copy[chunks[1].start as usize] = 0;
    std::fs::write(&damaged, &copy).unwrap();
    let recording = Recording::open(&damaged).unwrap();
    assert_eq!(read_all(&recording), (without(&written, chunks[1].times), None));
    assert!(recording.warnings()[0].contains("does not match the chunk index"), "{:?}", recording.warnings());
    copy = bytes.clone();
    copy[chunks[1].start as usize + 8] = 0x7f;
    std::fs::write(&damaged, &copy).unwrap();
    let recording = Recording::open(&damaged).unwrap();
    assert_eq!(read_all(&recording), (without(&written, chunks[1].times), None));
}

#[test]
fn devices_and_folders_in_place_of_a_file_are_refused() {
    let err = Recording::open(Path::new("/dev/zero")).err().unwrap();
    assert!(err.to_string().contains("not a regular file"), "{err}");
}
