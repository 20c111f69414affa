//! The type hashes the nodes announce equal those of an implementation written by others: rosbags'
//! `Typestore.hash_rihs01` — the standard types as ROS 2 Jazzy defines them (rosbags' own copy of
//! Jazzy's definitions, so our msgs/std copies are checked too), the project's types read by rosbags'
//! .msg parser from msgs/msg. The interpreter is `$SOFTCONTACT_PYTHON`, else `python3`.

use std::process::Command;

const SCRIPT: &str = r#"
import json, pathlib, sys
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
ours = json.loads(sys.argv[1])
store = get_typestore(Stores.ROS2_JAZZY)
for path in sorted(pathlib.Path(sys.argv[2]).glob("*.msg")):
    store.register(get_types_from_msg(path.read_text(), f"softcontact_msgs/msg/{path.stem}"))
bad = {t: (h, store.hash_rihs01(t)) for t, h in ours.items() if store.hash_rihs01(t) != h}
print(json.dumps(bad))
"#;

#[test]
fn every_type_hash_equals_rosbags_for_jazzy() {
    let ours: std::collections::BTreeMap<&str, String> = softcontact_msgs::DEFINITIONS
        .iter()
        .map(|(t, _)| (*t, softcontact_msgs::type_hash::rihs01(t).unwrap()))
        .collect();
    assert!(ours.len() >= 20, "{ours:?}");
    // The messages of ros2-client's own endpoints, whose hashes it announces from its table.
    let mut ours = ours;
    for path in [
        "rcl_interfaces/msg/Log",
        "rcl_interfaces/msg/ParameterEvent",
        "rmw_dds_common/msg/ParticipantEntitiesInfo",
        "rosgraph_msgs/msg/Clock",
        "action_msgs/msg/GoalStatusArray",
    ] {
        let dds = format!("{}_", path.replace('/', "::").replace("::msg::", "::msg::dds_::"));
        let hash =
            ros2_client::type_hashes::builtin(&dds).unwrap_or_else(|| panic!("{dds} not in ros2-client's table"));
        assert_eq!(ours.insert(path, hash.to_owned()).unwrap_or_else(|| hash.to_owned()), hash, "{path}");
    }
    // rosbags types a .msg `char` as FIELD_TYPE_CHAR; rosidl maps it to uint8 (its published
    // std_srvs/Trigger hash, which refers to ServiceEventInfo, is checked in src/type_hash.rs).
    let with_char = ours.remove("service_msgs/msg/ServiceEventInfo");
    assert!(with_char.is_some(), "ServiceEventInfo is defined in msgs/std");
    let python = std::env::var("SOFTCONTACT_PYTHON").unwrap_or_else(|_| "python3".into());
    let out = Command::new(&python)
        .args(["-c", SCRIPT, &serde_json::to_string(&ours).unwrap()])
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/msg"))
        .output()
        .unwrap_or_else(|e| panic!("cannot run {python}: {e}"));
    assert!(out.status.success(), "rosbags is needed (tools/test.sh): {}", String::from_utf8_lossy(&out.stderr));
    let differing = String::from_utf8_lossy(&out.stdout);
    assert_eq!(differing.trim(), "{}", "types whose hash differs (ours, rosbags'): {differing}");
}
