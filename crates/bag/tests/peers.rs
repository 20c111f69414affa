//! Peers no one here wrote (Python `mcap` + `mcap-ros2-support`, and `rosbags`) decode the project's
//! recordings value for value, and the project reads theirs value for value. Needs the packages of
//! requirements-test.txt.

mod common;

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use softcontact_bag::{AnyMessage, Recording};

fn peers(args: &[&Path]) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers.py");
    let out = Command::new("python3").arg(script).args(args).output().expect("python3");
    assert!(out.status.success(), "peers.py {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

fn json_of(msg: &AnyMessage) -> Value {
    serde_json::to_value(msg).unwrap()
}

#[test]
fn both_peers_decode_what_the_project_writes() {
    let dir = tempfile::tempdir().unwrap();
    for path in [dir.path().join("ours.mcap"), dir.path().join("ours_folder")] {
        let written = common::write_samples(&path, 20);
        let out = dir.path().join("decoded.json");
        peers(&[Path::new("decode"), &path, &out]);
        let decoded: Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
        for peer in ["mcap_ros2", "rosbags"] {
            let got = decoded[peer].as_array().unwrap();
            assert_eq!(got.len(), written.len(), "{peer}");
            for (g, (topic, t, msg)) in got.iter().zip(&written) {
                assert_eq!(g[0], topic.as_str(), "{peer}");
                assert_eq!(g[1], *t, "{peer} {topic}");
                assert_eq!(g[2], msg.type_path().as_str(), "{peer} {topic}");
                assert_eq!(g[3], json_of(msg), "{peer} {topic}");
            }
        }
    }
}

#[test]
fn the_project_reads_what_both_peers_write() {
    let dir = tempfile::tempdir().unwrap();
    peers(&[Path::new("write"), dir.path()]);
    let expected: Vec<Value> =
        serde_json::from_slice(&std::fs::read(dir.path().join("expected.json")).unwrap()).unwrap();
    for (source, path) in
        [("by_rosbags", dir.path().join("by_rosbags")), ("by_mcap_ros2", dir.path().join("by_mcap_ros2.mcap"))]
    {
        let recording = Recording::open(&path).unwrap();
        assert!(recording.warnings().is_empty(), "{source}: {:?}", recording.warnings());
        let want: Vec<&Value> = expected.iter().filter(|e| e[0] == source).collect();
        let mut n = 0;
        for (m, e) in recording.messages().zip(&want) {
            let m = m.unwrap();
            assert_eq!((m.topic(), m.log_time), (e[1].as_str().unwrap(), e[2].as_u64().unwrap()), "{source}");
            assert_eq!(softcontact_bag::type_path(m.type_name()), e[3].as_str().unwrap(), "{source}");
            let msg = AnyMessage::decode(&m).unwrap().expect("a type the project knows");
            assert_eq!(json_of(&msg), e[4], "{source} {}", m.topic());
            n += 1;
        }
        assert_eq!(n, want.len(), "{source}");
        assert_eq!(recording.message_count(), want.len() as u64, "{source}");
    }
}
