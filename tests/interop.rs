//! Other vendors' DDS as ROS 2 peers of the graph, each in its own graph run (`launch-scripts/sim.sh
//! --isolated`: sim_arm, lwr_control, contact_estimator in a network namespace with only loopback), with the
//! graph's `service_mapping` set for the peer's middleware. A peer built from that vendor's own tools
//! (tests/peers/) subscribes to the 1 kHz streams and /tf as a sensor subscriber and tf2's listener do,
//! lists and gets the controller's parameters and sends a force goal to the action, then prints what it
//! saw; this test judges it. The peers are built by `tests/peers/<vendor>/build.sh` (its packages are
//! installed by tools/test.sh).
//!
//! The Cyclone DDS peer does it once more on the graph under ROS 2 security (`sim.sh --secure`), enrolled
//! in the run's keystore as `/user` with Debian's security plugins: the same streams at 1 kHz, the same
//! parameter calls and a force goal that the controller executes, each authenticated, permitted by
//! `/user`'s signed permissions and encrypted. That run needs the `security` feature:
//! `cargo test --release --features softcontact/security -p softcontact --test interop enrolled`.
//!
//! And a trespasser: the Cyclone peer enrolled as `/user` with its own access control turned off (a
//! governance of its own, signed by the keystore's authority), so it creates a client of the sensor's bare
//! tare, which `/user`'s permissions lack. The graph's nodes never match that client: no answer. On the
//! plain graph the same call is answered (`cargo test … --test interop trespass`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use softcontact_msgs::softcontact_msgs::ControllerState;
use softcontact_msgs::topics;
use softcontact_nodes::runtime::ros;

#[path = "common/cyclone_security.rs"]
mod cyclone_security;

/// Set inside the namespace: the peer to run there.
const PEER: &str = "SOFTCONTACT_INTEROP_PEER";
/// Set inside the namespace to run the peer as a trespasser: it only calls the sensor's bare tare, which
/// only the controller may call (`trespass`, or `trespass-unchecked` with its own access control off).
const MODE: &str = "SOFTCONTACT_INTEROP_MODE";
/// The force goal the peers send [N] and its move's duration [s].
const GOAL: (f64, f64) = (20.0, 1.0);

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

static ONE_GRAPH_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn a_fast_dds_2_9_peer_reads_the_streams_and_tf_calls_the_parameter_services_and_sends_a_force_goal() {
    if let Ok(peer) = std::env::var(PEER) {
        return client(Path::new(&peer));
    }
    let test = "a_fast_dds_2_9_peer_reads_the_streams_and_tf_calls_the_parameter_services_and_sends_a_force_goal";
    let output = run_peer(test, "fastdds", "enhanced", "fastdds_peer", &[], "");
    judge(&output, "enhanced");
}

#[test]
fn a_cyclone_dds_0_10_peer_reads_the_streams_and_tf_calls_the_parameter_services_and_sends_a_force_goal() {
    if let Ok(peer) = std::env::var(PEER) {
        return client(Path::new(&peer));
    }
    let test = "a_cyclone_dds_0_10_peer_reads_the_streams_and_tf_calls_the_parameter_services_and_sends_a_force_goal";
    let output = run_peer(test, "cyclonedds", "cyclone", "cyclonedds_peer", &[], "");
    judge(&output, "cyclone");
    // The type hash each writer announces (a Jazzy build): the REP-2016 hash of its type — topics,
    // services' replies (rmw_cyclonedds' `rr/…Reply`), the action's and ros2-client's own endpoints.
    use softcontact_msgs::{RosType, topics, type_hash};
    let action = type_hash::press_force().unwrap();
    let builtin = |dds: &str| ros2_client::type_hashes::builtin(dds).map(str::to_owned);
    let reply = |service: &str| format!("rr{service}Reply");
    for (topic, hash) in [
        ("rt/lwr/joint_states".to_owned(), softcontact_msgs::sensor_msgs::JointState::type_hash()),
        ("rt/tf".to_owned(), softcontact_msgs::tf2_msgs::TFMessage::type_hash()),
        ("rt/ft_sensor/wrench".to_owned(), softcontact_msgs::geometry_msgs::WrenchStamped::type_hash()),
        (reply(topics::RETARE_SERVICE), type_hash::trigger()),
        (reply(topics::FT_BIAS_SERVICE), type_hash::trigger()),
        (reply(&format!("{}/_action/send_goal", topics::PRESS_ACTION)), Some(action.send_goal)),
        (reply(&format!("{}/_action/get_result", topics::PRESS_ACTION)), Some(action.get_result)),
        (format!("rt{}/_action/feedback", topics::PRESS_ACTION), Some(action.feedback_message)),
        (format!("rt{}/_action/status", topics::PRESS_ACTION), builtin("action_msgs::msg::dds_::GoalStatusArray_")),
        (reply("/deformation_controller/get_parameters"), builtin("rcl_interfaces::srv::dds_::GetParameters_")),
        ("ros_discovery_info".to_owned(), builtin("rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_")),
    ] {
        let announced = format!("user_data {topic} ");
        let line =
            output.lines().find(|l| l.starts_with(&announced)).unwrap_or_else(|| panic!("{topic}: no USER_DATA"));
        assert!(line.ends_with(&format!("typehash={};", hash.unwrap())), "{line}");
    }
}

#[test]
#[cfg_attr(not(feature = "security"), ignore = "needs the `security` feature (tools/test.sh builds with it)")]
fn an_enrolled_cyclone_dds_0_10_peer_reads_the_secure_graph_and_sends_a_force_goal_it_executes() {
    if let Ok(peer) = std::env::var(PEER) {
        return client(Path::new(&peer));
    }
    let test = "an_enrolled_cyclone_dds_0_10_peer_reads_the_secure_graph_and_sends_a_force_goal_it_executes";
    let output = run_peer(test, "cyclonedds", "cyclone", "cyclonedds_peer", &["--secure"], "");
    assert!(output.contains("launch: secure: keystore"), "the graph ran without security:\n{output}");
    assert!(output.contains("peer: enrolled as /user"), "the peer ran without credentials:\n{output}");
    judge(&output, "cyclone");
}

#[test]
#[cfg_attr(not(feature = "security"), ignore = "needs the `security` feature (tools/test.sh builds with it)")]
fn a_trespassing_peer_enrolled_without_the_tare_and_skipping_its_own_access_control_gets_no_answer() {
    if let Ok(peer) = std::env::var(PEER) {
        return client(Path::new(&peer));
    }
    let test = "a_trespassing_peer_enrolled_without_the_tare_and_skipping_its_own_access_control_gets_no_answer";
    // The control: on the plain graph the same call is answered, so the test can fail.
    let plain = run_peer(test, "cyclonedds", "cyclone", "cyclonedds_peer", &[], "trespass");
    for answered in ["bias answered", "get answered"] {
        assert!(peer_output(&plain).lines().any(|l| l == answered), "plain: {}", peer_output(&plain));
    }
    // Enrolled as /user, whose permissions lack the tare, with a governance of its own (signed by the
    // keystore's authority) that turns its own read and write checks off: it creates the writer, and the
    // graph's nodes never match it.
    let secure = run_peer(test, "cyclonedds", "cyclone", "cyclonedds_peer", &["--secure"], "trespass-unchecked");
    assert!(secure.contains("peer: own access control off"), "{secure}");
    let body = peer_output(&secure);
    assert!(!body.contains("no writer or reader"), "the peer checked itself after all: {body}");
    assert!(body.lines().any(|l| l == "bias unanswered"), "secure: {body}");
    // What its enclave grants still works in the same run: the peer is on the graph, only the tare is unmatched.
    assert!(body.lines().any(|l| l == "get answered"), "secure: {body}");
}

/// Builds the vendor's peer, starts the graph with `mapping` (and the launch script's `extra` options) and
/// runs the peer inside (`mode`: see [`MODE`]); the peer's output.
fn run_peer(test_name: &str, vendor: &str, mapping: &str, binary: &str, extra: &[&str], mode: &str) -> String {
    let build = Command::new(root().join(format!("tests/peers/{vendor}/build.sh"))).output().expect("build.sh runs");
    assert!(
        build.status.success(),
        "the {vendor} peer did not build (tools/test.sh installs its packages):\n{}",
        String::from_utf8_lossy(&build.stderr)
    );
    let peer = root().join(format!("target/peers/{vendor}/{binary}"));
    let _alone = ONE_GRAPH_AT_A_TIME.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    let logs = std::env::temp_dir().join(format!("softcontact-interop-{vendor}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&logs);
    std::fs::create_dir_all(&logs).unwrap();
    let overlay = logs.join("service_mapping.yaml");
    let section = |node: &str| format!("{node}:\n  ros__parameters:\n    service_mapping: {mapping}\n");
    std::fs::write(&overlay, section("deformation_controller") + &section("ft_sensor")).unwrap();
    let test = std::env::current_exe().unwrap();
    let out = Command::new(root().join("launch-scripts/sim.sh"))
        .arg("--isolated")
        .args(extra)
        .arg("--params-file")
        .arg(&overlay)
        .arg("--log-dir")
        .arg(&logs)
        .arg("--run")
        .arg(&test)
        .args(["--exact", test_name, "--nocapture", "--test-threads=1"])
        .env(PEER, &peer)
        .env(MODE, mode)
        .env("SOFTCONTACT_BIN", Path::new(env!("CARGO_BIN_EXE_softcontact")).parent().unwrap())
        .output()
        .expect("sim.sh runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    eprintln!("{text}");
    assert!(out.status.success() && text.contains("1 passed"), "the graph run failed (logs in {})", logs.display());
    let _ = std::fs::remove_dir_all(&logs);
    text
}

/// Inside the namespace, with the graph up: once the hand touches the sponge, the peer runs.
fn client(peer: &Path) {
    let mut node = ros::node("interop_test").unwrap();
    let states = ros::subscription(&mut node, &topics::CONTROLLER_STATE, ros::sensor_qos()).unwrap();
    let start = Instant::now();
    let mut in_contact = false;
    while !in_contact {
        assert!(start.elapsed() < Duration::from_secs(30), "no contact after 30 s");
        std::thread::sleep(Duration::from_millis(10));
        while let Ok(Some((s, _))) = states.take() {
            let s: ControllerState = s;
            in_contact |= s.in_contact;
        }
    }
    let mode = std::env::var(MODE).unwrap_or_default();
    let mut command = Command::new(peer);
    command.args([GOAL.0.to_string(), GOAL.1.to_string(), "3".into()]);
    if mode.starts_with("trespass") {
        command.arg("trespass");
    }
    // On the secure graph the command runs in /user's enclave: the peer is enrolled with its files.
    if let (Ok(keystore), Ok(enclave)) =
        (std::env::var("ROS_SECURITY_KEYSTORE"), std::env::var("ROS_SECURITY_ENCLAVE_OVERRIDE"))
    {
        let mut files = Path::new(&keystore).join("enclaves").join(enclave.trim_start_matches('/'));
        if mode == "trespass-unchecked" {
            files = without_own_access_control(Path::new(&keystore), &files);
            eprintln!("peer: own access control off");
        }
        command.env("CYCLONEDDS_URI", cyclone_security::cyclone_config(Some(&files)));
        eprintln!("peer: enrolled as {enclave} ({})", files.display());
    }
    let out = command.output().expect("the peer runs");
    // Between markers, for the outer test to judge.
    println!("peer output >>>\n{}<<< peer output", String::from_utf8_lossy(&out.stdout));
    eprintln!("{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "the peer failed: {:?}", out.status);
}

/// A copy of `enclave` whose governance, signed with the keystore's own permissions authority, turns read
/// and write access control off for the sensor's bare tare: a participant with it creates that service's
/// client whatever its permissions say, as one that skips its own checks would.
fn without_own_access_control(keystore: &Path, enclave: &Path) -> PathBuf {
    // Beside the keystore, in the run's folder (the copy holds the enclave's private key).
    let copy = keystore.parent().expect("the keystore is in the run's folder").join("unchecked_enclave");
    std::fs::create_dir_all(&copy).unwrap();
    for entry in std::fs::read_dir(enclave).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), copy.join(entry.file_name())).unwrap();
    }
    // The rule for every topic, `*`, copied for the tare's two topics with access control off, first.
    let governance = std::fs::read_to_string(keystore.join("enclaves/governance.xml")).unwrap();
    let start = governance.find("<topic_rule>").expect("a topic rule");
    let end = governance.find("</topic_rule>").expect("a topic rule") + "</topic_rule>".len();
    let every_topic = &governance[start..end];
    assert!(every_topic.contains("<topic_expression>*</topic_expression>"), "{every_topic}");
    let unchecked: String =
        [format!("rq{}Request", topics::FT_BIAS_SERVICE), format!("rr{}Reply", topics::FT_BIAS_SERVICE)]
            .iter()
            .map(|topic| {
                every_topic
                    .replace("<topic_expression>*<", &format!("<topic_expression>{topic}<"))
                    .replace("<enable_read_access_control>true", "<enable_read_access_control>false")
                    .replace("<enable_write_access_control>true", "<enable_write_access_control>false")
                    + "\n        "
            })
            .collect();
    let unchecked = format!("{}{unchecked}{}", &governance[..start], &governance[start..]);
    std::fs::write(copy.join("governance.xml"), unchecked).unwrap();
    let signed = Command::new("openssl")
        .current_dir(&copy)
        .args(["smime", "-sign", "-text", "-in", "governance.xml", "-out", "governance.p7s", "-signer"])
        .arg(keystore.join("public/permissions_ca.cert.pem"))
        .arg("-inkey")
        .arg(keystore.join("private/permissions_ca.key.pem"))
        .status()
        .expect("openssl runs");
    assert!(signed.success(), "openssl signed the governance");
    copy
}

/// What the peer printed, between the client's markers.
fn peer_output(text: &str) -> &str {
    text.split("peer output >>>\n").nth(1).and_then(|t| t.split("<<< peer output").next()).unwrap_or("")
}

/// The peer's `key value…` lines.
fn judge(text: &str, mapping: &str) {
    let body = peer_output(text);
    let line = |key: &str| -> Vec<String> {
        let l =
            body.lines().find(|l| l.starts_with(&format!("{key} "))).unwrap_or_else(|| panic!("no `{key}`: {body}"));
        l.split_whitespace().skip(1).map(str::to_owned).collect()
    };
    let num = |v: &str| v.parse::<f64>().unwrap_or_else(|_| panic!("`{v}` is not a number: {body}"));
    // 3 s of the 1 kHz streams, best effort; every sample decoded with the URDF's names and its frame.
    let joints = line("joint_states");
    assert!(num(&joints[0]) > 1500.0 && joints[0] == joints[1], "joint states: {joints:?}");
    let wrenches = line("wrenches");
    assert!(num(&wrenches[0]) > 1500.0 && wrenches[0] == wrenches[1], "wrenches: {wrenches:?}");
    // /tf as tf2 reads it: reliable, 100 Hz, stamps rising, world → lwr_tool.
    let tf = line("tf");
    assert!((200.0..=330.0).contains(&num(&tf[0])) && tf[1..] == ["1", "world", "lwr_tool"], "/tf: {tf:?}");
    // The controller's parameters: all of them listed; a double and a string got by name.
    assert!(num(&line("parameters")[0]) >= 20.0, "parameters listed: {body}");
    let get = line("get");
    assert_eq!(get[..2], ["force_limit", "3"], "{get:?}");
    assert!(num(&get[2]) > 0.0 && get[3..] == ["service_mapping", "4", mapping], "{get:?}");
    // The force goal: accepted, ended (status 4: succeeded), its result's error the force less the goal.
    assert_eq!(line("goal"), ["accepted", "1"]);
    let result = line("result");
    let (status, force, error) = (num(&result[0]), num(&result[1]), num(&result[2]));
    assert_eq!(status, 4.0, "result: {result:?}");
    assert!(force > 1.0 && (error - (force - GOAL.0)).abs() < 2e-3, "result: {result:?}");
}
