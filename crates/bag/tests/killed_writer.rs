//! A recording whose writer process is killed (SIGKILL, no chance to clean up) keeps everything it
//! flushed, and reads back with warnings, not an error.

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

use softcontact_bag::{AnyMessage, BagWriter, Recording};

const CHILD: &str = "SOFTCONTACT_BAG_WRITER_CHILD";

/// The writer: in a child process only (this test binary re-executed), writes rounds of every message
/// type until it is killed, flushing every 100 rounds and telling how many messages are flushed.
#[test]
fn writer_child() {
    let Ok(path) = std::env::var(CHILD) else { return };
    let mut writer = BagWriter::create(std::path::Path::new(&path)).unwrap();
    let mut count = 0u64;
    for i in 0..2_000_000u32 {
        for (topic, msg) in common::samples(i) {
            msg.write(&mut writer, topic, common::qos_of(topic), common::T0 + i as u64 * 1_000_000).unwrap();
            count += 1;
        }
        if i % 100 == 99 {
            writer.flush().unwrap();
            println!("flushed {count}");
        }
    }
    panic!("the writer was not killed");
}

#[test]
fn a_killed_writer_loses_nothing_it_flushed() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("killed");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "writer_child", "--nocapture", "--test-threads", "1"])
        .env(CHILD, &folder)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut flushed = 0u64;
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    for line in lines.by_ref() {
        if let Some(n) = line.unwrap().strip_prefix("flushed ") {
            flushed = n.parse().unwrap();
            if flushed >= 13 * 2000 {
                break;
            }
        }
    }
    child.kill().unwrap(); // SIGKILL: mid-chunk, no summary, no metadata.yaml
    child.wait().unwrap();
    drop(lines);

    let recording = Recording::open(&folder).unwrap();
    let warnings = recording.warnings().join("\n");
    assert!(warnings.contains("no metadata.yaml") && warnings.contains("not closed by its writer"), "{warnings}");
    let mut read = 0u64;
    for (i, m) in recording.messages().enumerate() {
        let m = m.unwrap();
        let round = (i / 13) as u32;
        let (topic, want) = common::samples(round).swap_remove(i % 13);
        assert_eq!((m.topic(), m.log_time), (topic, common::T0 + round as u64 * 1_000_000));
        assert_eq!(AnyMessage::decode(&m).unwrap().unwrap(), want);
        read += 1;
    }
    assert!(read >= flushed, "read {read}, flushed {flushed}");
    assert_eq!(read, recording.message_count());
}
