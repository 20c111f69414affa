//! The real graph, as users start it: `launch-scripts/sim.sh --isolated` brings up sim_arm, the 1 kHz path
//! composed in one process (`lwr_control`: driver, F/T node, controller) and the contact estimator over DDS
//! in a network namespace with only loopback, and this test runs inside it as a user would: it waits for
//! contact, has the controller push the sponge at 1 Hz while the estimator learns it, checks the learned
//! model against the simulator's surface, publishes a stranger's torque commands (the composed driver takes
//! none from the network), sends 5 force commands with the `softcontact force` command and checks each is
//! reached within 5 %, and lets a Cyclone DDS peer (Python) read two topics. Outside, it checks that every
//! process stopped cleanly, that the driver answered the KRC within 200 µs (from the kernel's receive
//! timestamp) in most cycles with a median well under that, each answered with a torque computed for that measurement once
//! control began, and each process's peak memory. The latency goal itself is a benchmark,
//! `softcontact bench graph`: here the test shares 2 cores with Python peers and a recorder.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use ros2_client::{Name, ServiceTypeName};
use softcontact_msgs::softcontact_msgs::{ContactModel, ControllerState, ForceCommand};
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use softcontact_nodes::runtime::ros;

const INSIDE: &str = "SOFTCONTACT_GRAPH_CLIENT";
const REPLAY_INSIDE: &str = "SOFTCONTACT_REPLAY_CLIENT";
const LOCKSTEP_INSIDE: &str = "SOFTCONTACT_LOCKSTEP_CLIENT";
/// Where the client records the graph with `softcontact record`.
const RECORDING: &str = "SOFTCONTACT_GRAPH_RECORDING";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

#[test]
fn the_graph_reaches_force_commands_on_the_sponge() {
    if std::env::var(INSIDE).is_ok() {
        return client();
    }
    if let Ok(recording) = std::env::var(REPLAY_INSIDE) {
        return replay_client(Path::new(&recording));
    }
    let logs = std::env::temp_dir().join(format!("softcontact-graph-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&logs);
    std::fs::create_dir_all(&logs).unwrap();
    let recording = logs.join("graph_recording");
    let passed = sim_sh(GRAPH_TEST, &[], &logs, &[(INSIDE, Path::new("1")), (RECORDING, &recording)]);
    assert!(passed, "the graph run failed (logs in {})", logs.display());

    let log = |n: &str| std::fs::read_to_string(logs.join(format!("{n}.log"))).unwrap();
    // Processes and the nodes each hosts (peak memory goal: 30 MB a node).
    for (n, hosted) in [("sim_arm", 1.0), ("lwr_control", 3.0), ("contact_estimator", 1.0)] {
        let l = log(n);
        assert!(l.contains("exit"), "{n} wrote its exit report:\n{l}");
        let rss: f64 = number_after(&l, "peak RSS ").unwrap_or_else(|| panic!("{n} reports its memory"));
        assert!(rss < 30.0 * hosted, "{n}: peak RSS {rss} MB (goal < 30 MB a node, {hosted} hosted)");
    }
    let driver = log("lwr_control");
    let within = number_after(&driver, "within 200 us: ").expect("reply latency reported");
    let median: f64 = driver
        .lines()
        .find_map(|l| l.split("reply latency n ").nth(1)?.split(" p50 ").nth(1)?.split(' ').next()?.parse().ok())
        .expect("the reply latency's median reported");
    eprintln!("graph: FRI answers within 200 us in {within} % of cycles, median {median} us");
    // Bounds that catch a loop gone slow (most replies late), not the goal: `softcontact bench graph`
    // measures that (97–98 % within 200 us, the hand resting on the sponge). Here the graph shares 2 cores
    // with Python peers, a recorder and the test harness: a healthy loop shows a median of 30–40 us and
    // 93–96 % within 200 us, the tail set by the machine's load, not by the loop.
    assert!(median <= 100.0, "the FRI answer's median is {median} us");
    assert!(within >= 80.0, "FRI answers within 200 us in {within} % of cycles");
    // Goal 0; a little room for a loaded CI machine (a stall of the F/T thread beyond stale_after).
    let stale: f64 = driver
        .lines()
        .find_map(|l| l.split("stale cycles ").nth(1)?.split(", ").nth(1)?.split(' ').next()?.parse().ok())
        .expect("stale cycles after the first command");
    assert!(stale <= 5.0, "{stale} cycles answered with a held command after control began (goal 0)");

    check_recording(&recording, &logs);

    // The recording replayed into a contact estimator alone (its own namespace) learns the same model.
    let replay_logs = logs.join("replay");
    let passed = sim_sh(GRAPH_TEST, &["--nodes", "contact_estimator"], &replay_logs, &[(REPLAY_INSIDE, &recording)]);
    assert!(passed, "the replay run failed (logs in {})", replay_logs.display());
    let _ = std::fs::remove_dir_all(&logs);
}

/// The separate layout (`sim.sh --separate`: driver, F/T node and controller each a process, the torque
/// loop over DDS) against a stranger on its DDS domain who does what an adversarial test did: joint states
/// stamped 100 s ahead (which silenced the controller), then zero wrenches and torque commands copied from
/// the live joint states with 8 N·m more on joint 4 (which drove the arm past a limit). Each node takes
/// its streams from one writer (the first, while it is the only one): the controller goes on commanding,
/// the stranger's samples are counted and refused, and no joint trips a fault.
#[test]
fn the_separate_layout_takes_nothing_from_a_stranger_on_its_domain() {
    if std::env::var(SEPARATE_INSIDE).is_ok() {
        return stranger_client();
    }
    let logs = std::env::temp_dir().join(format!("softcontact-separate-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&logs);
    std::fs::create_dir_all(&logs).unwrap();
    let passed = sim_sh(SEPARATE_TEST, &["--separate"], &logs, &[(SEPARATE_INSIDE, Path::new("1"))]);
    assert!(passed, "the separate run failed (logs in {})", logs.display());
    let driver = std::fs::read_to_string(logs.join("lwr_driver.log")).unwrap();
    let controller = std::fs::read_to_string(logs.join("deformation_controller.log")).unwrap();
    let estimator = std::fs::read_to_string(logs.join("contact_estimator.log")).unwrap();
    let count = |text: &str, key: &str| number_after(text, key).unwrap_or_else(|| panic!("`{key}` reported"));
    // The estimator's wrenches and the controller's models come from their one writer too.
    let refused_by_estimator = count(&estimator, " twists, ");
    assert!(refused_by_estimator > 500.0, "the estimator took the stranger's wrenches: {estimator}");
    assert!(controller.contains("model refused"), "the controller took the stranger's model: {controller}");
    let refused_commands = count(&driver, "commands_from_strangers: ");
    let refused_states = count(&controller, "pinned ones: ");
    let refused_wrenches = count(&controller, " joint states, ");
    eprintln!(
        "separate: refused from the stranger {refused_commands} torque commands, {refused_states} joint states, {refused_wrenches} wrenches"
    );
    assert!(refused_commands > 500.0 && refused_wrenches > 500.0 && refused_states >= 5.0);
    assert_eq!(count(&driver, "overspeed_cycles: ") + count(&driver, "limit_cycles: "), 0.0, "{driver}");
    let _ = std::fs::remove_dir_all(&logs);
}

/// Inside the separate graph: the stranger.
fn stranger_client() {
    use softcontact_msgs::geometry_msgs::WrenchStamped;
    use softcontact_msgs::sensor_msgs::JointState;
    let mut node = ros::node("stranger").unwrap();
    let states =
        ros::subscription_by_name::<ControllerState>(&mut node, "/deformation_controller/state", ros::sensor_qos())
            .unwrap();
    let joints = ros::subscription_by_name::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos()).unwrap();
    let commands =
        ros::subscription_by_name::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos()).unwrap();
    let start = Instant::now();
    let mut in_contact = 0;
    while in_contact < 500 {
        while let Ok(Some((s, _))) = states.take() {
            in_contact += usize::from(s.in_contact);
        }
        assert!(start.elapsed() < Duration::from_secs(30), "no contact after 30 s");
        std::thread::sleep(Duration::from_millis(1));
    }
    // Writers of the stranger's own, created only now: the graph's nodes have pinned theirs.
    let forged_states =
        ros::publisher_by_name::<JointState>(&mut node, "/lwr/joint_states", ros::reliable_qos()).unwrap();
    let wrenches = ros::publisher_by_name::<WrenchStamped>(&mut node, "/ft_sensor/wrench", ros::sensor_qos()).unwrap();
    let torques =
        ros::publisher_by_name::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos()).unwrap();
    let models = ros::publisher_by_name::<softcontact_nodes::contact_estimator::ModelMsg>(
        &mut node,
        "/contact_estimator/model",
        ros::reliable_qos(),
    )
    .unwrap();
    let stranger = torques.gid();
    std::thread::sleep(Duration::from_millis(500)); // discovery
    let newest = |joints: &ros2_client::Subscription<JointState>| {
        let mut newest = None;
        while let Ok(Some((js, _))) = joints.take() {
            newest = Some(js);
        }
        newest
    };
    let live = loop {
        if let Some(js) = newest(&joints) {
            break js;
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    for _ in 0..5 {
        let mut ahead = live.clone();
        ahead.header.stamp.sec += 100;
        forged_states.publish(ahead).unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }
    // A plausible model, ten times too soft, with the surface 9.5 mm deeper: the controller would press
    // far harder than commanded through it.
    let soft = softcontact_nodes::contact_estimator::ModelMsg {
        kind: "kelvin_voigt".into(),
        stiffness: 200.0,
        damping: 10.0,
        exponent_a: 1.0,
        exponent_b: 0.0,
        exponent_c: 1.0,
        contact_position: softcontact_msgs::geometry_msgs::Point { x: 0.0, y: 0.0, z: -0.0095 },
        ..Default::default()
    };
    for _ in 0..3 {
        models.publish(soft.clone()).unwrap();
    }
    let model = softcontact_dynamics::lwr4::model();
    let mut data = model.data();
    let (mut controller_commands, mut forged) = (0, 0);
    let attack = Instant::now();
    while attack.elapsed() < Duration::from_secs(2) {
        while let Ok(Some((_, info))) = commands.take() {
            controller_commands += usize::from(info.publisher_gid() != stranger);
        }
        if let Some(js) = newest(&joints) {
            let mut effort: Vec<f64> = model.gravity_torques(&mut data, &js.position).iter().copied().collect();
            effort[3] += 8.0;
            torques.publish(JointState { header: js.header.clone(), effort, ..Default::default() }).unwrap();
            let mut w = WrenchStamped::default();
            w.header.stamp = js.header.stamp;
            w.header.frame_id = "ft_sensor".into();
            wrenches.publish(w).unwrap();
            forged += 1;
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    eprintln!("stranger: {forged} forged commands and wrenches; the controller sent {controller_commands} in 2 s");
    assert!(forged > 1000, "the stranger kept up: {forged}");
    assert!(controller_commands > 1000, "the controller was not silenced: {controller_commands} commands in 2 s");
    let mut still_in_contact = false;
    while let Ok(Some((s, _))) = states.take() {
        still_in_contact = s.in_contact;
    }
    assert!(still_in_contact, "the hand stayed on the sponge");
}

const SEPARATE_TEST: &str = "the_separate_layout_takes_nothing_from_a_stranger_on_its_domain";
const SEPARATE_INSIDE: &str = "SOFTCONTACT_SEPARATE_CLIENT";
const GRAPH_TEST: &str = "the_graph_reaches_force_commands_on_the_sponge";
const LOCKSTEP_TEST: &str = "the_lockstep_graph_runs_the_controller_on_the_simulated_clock";

/// The lockstep graph (`sim.sh --lockstep`: faster than real time, every node on /clock): the controller
/// runs on the clock it is given — each FRI measurement stamped with the simulated KRC's own time and
/// answered with a torque for it (a stamp taken from /clock, which can lag the datagram, repeated and
/// left most measurements held) — and it finds the surface.
#[test]
fn the_lockstep_graph_runs_the_controller_on_the_simulated_clock() {
    if std::env::var(LOCKSTEP_INSIDE).is_ok() {
        return lockstep_client();
    }
    let logs = std::env::temp_dir().join(format!("softcontact-lockstep-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&logs);
    std::fs::create_dir_all(&logs).unwrap();
    let passed = sim_sh(LOCKSTEP_TEST, &["--lockstep"], &logs, &[(LOCKSTEP_INSIDE, Path::new("1"))]);
    assert!(passed, "the lockstep run failed (logs in {})", logs.display());
    let log = std::fs::read_to_string(logs.join("lwr_control.log")).unwrap();
    let sent = number_after(&log, "deformation_controller: exit: ").expect("the controller's exit report");
    let not_newer = number_after(&log, " restarts, ").expect("joint states not newer");
    let stale: f64 = log
        .lines()
        .find_map(|l| l.split("stale cycles ").nth(1)?.split(", ").nth(1)?.split(' ').next()?.parse().ok())
        .expect("stale cycles after the first command");
    eprintln!("lockstep: {sent} commands sent, {not_newer} joint states not newer, {stale} stale after the first");
    assert!(sent > 2000.0, "the controller ticked: {sent} commands");
    assert_eq!(not_newer, 0.0, "every joint state newer than the last (stamped on the KRC's clock)");
    // Goal 0 (it was 53 000 of 56 000 with stamps from /clock). A loaded CI machine stalls the simulator
    // now and then: its FRI and RDT datagrams then leave together, a measurement can reach the driver
    // before the F/T node has relayed the force, and the controller rightly holds on a force older than
    // its stale_after (8 such cycles in 8374 on one clean-clone run, with 3 new KRC sessions). Room for
    // that — 0.5 % of the commands — and still 190 times below the failure this test guards against.
    assert!(stale <= (0.005 * sent).max(5.0), "{stale} measurements answered with a held command once control began");
    let _ = std::fs::remove_dir_all(&logs);
}

/// Inside the lockstep graph: the hand finds the sponge, in simulated time.
fn lockstep_client() {
    let mut node = ros::node("lockstep_test").unwrap();
    let states =
        ros::subscription_by_name::<ControllerState>(&mut node, "/deformation_controller/state", ros::sensor_qos())
            .unwrap();
    let start = Instant::now();
    let mut holding = 0;
    while holding < 200 {
        if let Ok(Some((s, _))) = states.take() {
            holding += usize::from(s.in_contact);
        } else {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(start.elapsed() < Duration::from_secs(30), "no contact in lockstep after 30 s");
    }
}

/// `sim.sh --isolated [options] --run <the test `name`, as the client the environment selects>`; whether
/// the graph ran and the client passed.
/// One graph at a time: the lockstep graph runs flat out on both cores, and beside it the real-time graph
/// would miss its latency goal (the test harness runs this file's tests in parallel).
static ONE_GRAPH_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn sim_sh(name: &str, options: &[&str], logs: &Path, env: &[(&str, &Path)]) -> bool {
    let _alone = ONE_GRAPH_AT_A_TIME.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    let out = Command::new(root().join("launch-scripts/sim.sh"))
        .arg("--isolated")
        .args(options)
        .arg("--log-dir")
        .arg(logs)
        .arg("--run")
        .arg(std::env::current_exe().unwrap())
        .args(["--exact", name, "--nocapture", "--test-threads=1"])
        .envs(env.iter().copied())
        .env("SOFTCONTACT_BIN", Path::new(env!("CARGO_BIN_EXE_softcontact")).parent().unwrap())
        .output()
        .expect("sim.sh runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    eprintln!("{text}");
    out.status.success() && text.contains("1 passed")
}

/// The recording the client made: complete, read by both Python peers as the project reads it, and
/// `softcontact identify` chooses the simulator's model kind from it.
fn check_recording(recording: &Path, logs: &Path) {
    let rec = softcontact_bag::Recording::open(recording).unwrap();
    assert!(rec.warnings().is_empty(), "{:?}", rec.warnings());
    for topic in ["/ft_sensor/wrench", "/lwr/ee_pose", "/lwr/ee_twist", "/lwr/joint_states", "/tf_static"] {
        assert!(rec.topic(topic).is_some_and(|t| t.message_count > 0), "{topic} recorded");
    }
    // The wrench's own rate, between its first and last message: the recording's span also holds the
    // seconds before the wrench's subscription matched (/tf_static, latched, comes at once).
    let (mut first, mut last, mut wrenches) = (u64::MAX, 0, 0u64);
    for m in rec.messages().map(Result::unwrap).filter(|m| m.topic() == "/ft_sensor/wrench") {
        (first, last, wrenches) = (first.min(m.log_time), last.max(m.log_time), wrenches + 1);
    }
    let rate = (wrenches - 1) as f64 / ((last - first) as f64 * 1e-9);
    let (t0, t1) = rec.time_range().unwrap();
    eprintln!(
        "recording: {} messages over {:.1} s, /ft_sensor/wrench at {rate:.0} Hz over its {:.1} s",
        rec.message_count(),
        (t1 - t0) as f64 * 1e-9,
        (last - first) as f64 * 1e-9
    );
    // Catches a publisher or recorder that lost its rate, not a few late samples on a loaded machine.
    assert!(rate > 800.0, "the wrench recorded at {rate} Hz (published at 1 kHz)");

    let json = logs.join("identify.json");
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .arg("identify")
        .arg(recording)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    eprint!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "identify ran");
    let id: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let sponge = softcontact_sim::sponge();
    let truth = softcontact_sim::SimConfig::above_surface(sponge.clone(), 1).surface.unwrap().point;
    assert_eq!(id["selected"], sponge.kind.id(), "identify chooses the simulator's kind");
    assert!((id["contact_position"][2].as_f64().unwrap() - truth.z).abs() < 1e-3, "surface within 1 mm");
    let k = id["selected_at_contact_position"]["stiffness"].as_f64().unwrap();
    assert!((k / sponge.stiffness - 1.0).abs() < 0.1, "k {k} within 10 % of {}", sponge.stiffness);

    // Both Python peers: the same messages per topic, and the models value for value.
    let decoded = logs.join("peers.json");
    let out = Command::new("python3")
        .arg(root().join("crates/bag/tests/peers.py"))
        .args(["decode"])
        .arg(recording)
        .arg(&decoded)
        .args(["/contact_estimator/model", "/tf_static"])
        .output()
        .unwrap();
    assert!(out.status.success(), "peers.py: {}", String::from_utf8_lossy(&out.stderr));
    let decoded: serde_json::Value = serde_json::from_slice(&std::fs::read(&decoded).unwrap()).unwrap();
    let models: Vec<serde_json::Value> = rec
        .messages()
        .map(Result::unwrap)
        .filter(|m| m.topic() == "/contact_estimator/model" || m.topic() == "/tf_static")
        .map(|m| serde_json::to_value(softcontact_bag::AnyMessage::decode(&m).unwrap().unwrap()).unwrap())
        .collect();
    assert!(models.len() > 5, "models recorded");
    for peer in ["mcap_ros2", "rosbags"] {
        for t in rec.topics() {
            assert_eq!(decoded["counts"][peer][&t.name], t.message_count, "{peer} {}", t.name);
        }
        let got: Vec<&serde_json::Value> = decoded[peer].as_array().unwrap().iter().map(|m| &m[3]).collect();
        assert_eq!(got, models.iter().collect::<Vec<_>>(), "{peer}");
    }
}

/// Inside the replay namespace, where only contact_estimator runs: `softcontact replay` the sensor
/// and pose topics into it; its last model equals the last one recorded.
fn replay_client(recording: &Path) {
    let rec = softcontact_bag::Recording::open(recording).unwrap();
    let recorded: ContactModel = rec
        .messages()
        .map(Result::unwrap)
        .filter(|m| m.topic() == "/contact_estimator/model")
        .map(|m| m.decode::<ContactModel>().unwrap())
        .last()
        .expect("a model recorded");
    // A Cyclone DDS peer asks the estimator for its parameters in its own request mapping (`ros2 param`
    // over rmw_cyclonedds) — here, where no FRI latency is measured, as a Python peer loads the CPU.
    let out = Command::new("python3")
        .arg(root().join("tests/parameters_cyclonedds.py"))
        .args(["contact_estimator", "refit_period=1.0", "max_relative_error=0.25"])
        .output()
        .expect("python3 runs");
    eprint!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "the Cyclone DDS peer got the estimator's parameters");
    let mut node = ros::node("replay_test").unwrap();
    let models =
        ros::subscription_by_name::<ContactModel>(&mut node, "/contact_estimator/model", ros::reliable_qos()).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .arg("replay")
        .arg(recording)
        .args(["--topics", "/ft_sensor/wrench,/lwr/ee_pose,/lwr/ee_twist,/tf_static"])
        .output()
        .unwrap();
    eprint!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "replay ran");
    std::thread::sleep(Duration::from_millis(1500)); // the last refit
    let mut last = None;
    while let Ok(Some((m, _))) = models.take() {
        last = Some(m);
    }
    let learned = last.expect("the estimator published models during the replay");
    eprintln!(
        "replayed: {} k {:.0} λ {:.0} z {:.4}; recorded: {} k {:.0} λ {:.0} z {:.4}",
        learned.kind,
        learned.stiffness,
        learned.damping,
        learned.contact_position.z,
        recorded.kind,
        recorded.stiffness,
        recorded.damping,
        recorded.contact_position.z
    );
    assert_eq!(learned.kind, recorded.kind);
    assert!((learned.stiffness / recorded.stiffness - 1.0).abs() < 0.02, "k within 2 %");
    assert!((learned.contact_position.z - recorded.contact_position.z).abs() < 5e-4, "surface within 0.5 mm");
}

/// The number that follows `key` in `text` (its last occurrence).
fn number_after(text: &str, key: &str) -> Option<f64> {
    let rest = &text[text.rfind(key)? + key.len()..];
    rest.split(|c: char| !(c.is_ascii_digit() || c == '.')).next()?.parse().ok()
}

/// Inside the namespace, with the graph up.
fn client() {
    // Everything the graph says, recorded as a user would (stopped after the identification pushes).
    let mut recorder = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .arg("record")
        .arg("-o")
        .arg(std::env::var(RECORDING).unwrap())
        .spawn()
        .unwrap();
    let mut node = ros::node("graph_test").unwrap();
    let states =
        ros::subscription_by_name::<ControllerState>(&mut node, "/deformation_controller/state", ros::sensor_qos())
            .unwrap();
    let models =
        ros::subscription_by_name::<ContactModel>(&mut node, "/contact_estimator/model", ros::reliable_qos()).unwrap();
    let commands =
        ros::publisher_by_name::<ForceCommand>(&mut node, "/deformation_controller/force_command", ros::reliable_qos())
            .unwrap();
    let mut latest_model: Option<ContactModel> = None;
    let mut latest_state: Option<ControllerState> = None;
    let drain = |latest_model: &mut Option<ContactModel>, latest_state: &mut Option<ControllerState>| {
        while let Ok(Some((m, _))) = models.take() {
            *latest_model = Some(m);
        }
        while let Ok(Some((s, _))) = states.take() {
            *latest_state = Some(s);
        }
    };

    // The hand starts 4 cm above the sponge and descends at 1 cm/s.
    let start = Instant::now();
    while !latest_state.as_ref().is_some_and(|s| s.in_contact) {
        assert!(start.elapsed() < Duration::from_secs(30), "no contact after 30 s: {latest_state:?}");
        std::thread::sleep(Duration::from_millis(10));
        drain(&mut latest_model, &mut latest_state);
    }
    eprintln!("contact after {:.1} s", start.elapsed().as_secs_f64());
    std::thread::sleep(Duration::from_millis(300)); // the controller's reader matches this writer

    // Identification pushes at 1 Hz (the force-control paper), until the window is full; the controller adopts the
    // newest model at each push.
    let start = Instant::now();
    'push: loop {
        for force in [100.0, 30.0] {
            commands.publish(ForceCommand { force, duration: 0.5 }).unwrap();
            let until = Instant::now() + Duration::from_millis(500);
            while Instant::now() < until {
                std::thread::sleep(Duration::from_millis(10));
                drain(&mut latest_model, &mut latest_state);
                assert!(!latest_state.as_ref().unwrap().contact_lost, "contact lost while pushing");
            }
        }
        if latest_model.as_ref().is_some_and(|m| m.window_fill > 0.99) {
            break 'push;
        }
        assert!(start.elapsed() < Duration::from_secs(40), "window not filled in 40 s: {latest_model:?}");
    }
    // One more refit on the full window.
    std::thread::sleep(Duration::from_millis(1100));
    drain(&mut latest_model, &mut latest_state);
    let stopped = Command::new("kill").args(["-INT", &recorder.id().to_string()]).status().unwrap();
    assert!(stopped.success() && recorder.wait().unwrap().success(), "the recorder stopped cleanly on SIGINT");
    let m = latest_model.clone().unwrap();
    let sponge = softcontact_sim::sponge();
    let truth = softcontact_sim::SimConfig::above_surface(sponge.clone(), 1).surface.unwrap().point;
    eprintln!(
        "learned {} k {:.0} λ {:.0} surface z {:.4} (truth {} k {:.0}, z {:.4}); fitness {:?} of {:?}",
        m.kind,
        m.stiffness,
        m.damping,
        m.contact_position.z,
        sponge.kind.id(),
        sponge.stiffness,
        truth.z,
        m.candidate_fitness_mean,
        m.candidate_kinds
    );
    assert_eq!(m.kind, sponge.kind.id(), "the sponge's kind is chosen");
    assert!((m.stiffness / sponge.stiffness - 1.0).abs() < 0.1, "k within 10 %");
    assert!((m.contact_position.z - truth.z).abs() < 1e-3, "surface within 1 mm");

    // A stranger's torque commands, stamped and in the driver's session as the controller's would be:
    // the composed driver takes none from the network, so the hold at contact is not disturbed.
    let stranger = ros::publisher_by_name::<softcontact_msgs::sensor_msgs::JointState>(
        &mut node,
        "/lwr/joint_torque_command",
        ros::reliable_qos(),
    )
    .unwrap();
    let held_at = latest_state.as_ref().unwrap().z;
    for _ in 0..200 {
        let stamp = softcontact_msgs::builtin_interfaces::Time::now();
        let header = softcontact_msgs::std_msgs::Header { stamp, frame_id: "krc_session_1_command".into() };
        let names = (1..=7).map(|i| format!("lwr_a{i}_joint")).collect::<Vec<_>>();
        let command =
            softcontact_nodes::messages::torque_command(&names, &[0.0, 150.0, 0.0, -150.0, 0.0, 0.0, 0.0], &header);
        stranger.publish(command).unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }
    std::thread::sleep(Duration::from_millis(200));
    drain(&mut latest_model, &mut latest_state);
    let z = latest_state.as_ref().unwrap().z;
    assert!((z - held_at).abs() < 1e-3, "the stranger's torques moved the hand: deformation {held_at} → {z} m");

    // Five force commands from the command line, each checked at the end of its 2 s move.
    let mut last = 0.0;
    for ratio in [0.5, 0.3, 0.7, 0.4, 0.6] {
        let force = ratio * 280.0;
        let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
            .args(["force", &force.to_string(), "--duration", "2", "--tolerance", "0.05"])
            .output()
            .unwrap();
        let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        eprint!("{text}");
        assert!(out.status.success(), "{force} N not reached within 5 %");
        last = force;
    }
    // One beyond max_force: refused, with the controller's reason, and the hold unchanged.
    let out =
        Command::new(env!("CARGO_BIN_EXE_softcontact")).args(["force", "600", "--duration", "2"]).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    eprint!("{text}");
    assert!(!out.status.success(), "600 N taken");
    assert!(text.contains("refused 600.0 N over 2.0 s: force command 600.0 N is outside [0, "), "{text}");

    // A peer on another DDS implementation reads the wrench and the controller state at the last hold.
    let out = Command::new("python3")
        .arg(root().join("tests/interop_cyclonedds.py"))
        .arg(last.to_string())
        .output()
        .expect("python3 runs");
    eprint!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "the Cyclone DDS peer decoded both topics");

    // Retreat and re-tare (/deformation_controller/retare): the hand lifts off, the F/T node tares with it
    // free and still, the controller finds the surface again, and a force is reached as before.
    let retare = node
        .create_client::<TriggerRequest, TriggerResponse>(
            ros::service_mapping("cyclone").unwrap(),
            &Name::new("/deformation_controller", "retare").unwrap(),
            &ServiceTypeName::new("std_srvs", "Trigger"),
            ros::reliable_qos(),
            ros::reliable_qos(),
        )
        .unwrap();
    std::thread::sleep(Duration::from_millis(500)); // discovery
    let request = retare.send_request(TriggerRequest::default()).unwrap();
    let start = Instant::now();
    let mut least_force = f64::INFINITY;
    let response = loop {
        drain(&mut latest_model, &mut latest_state);
        least_force = least_force.min(latest_state.as_ref().unwrap().f);
        if let Ok(Some((id, r))) = retare.receive_response()
            && id == request
        {
            break r;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "no answer to the re-tare in 10 s");
        std::thread::sleep(Duration::from_millis(10));
    };
    eprintln!("retare: {} after {:.1} s: {}", response.success, start.elapsed().as_secs_f64(), response.message);
    assert!(response.success, "re-tared: {}", response.message);
    assert!(least_force < 1.0, "the hand was free: {least_force} N at least");
    let (mut approached, start) = (false, Instant::now());
    loop {
        drain(&mut latest_model, &mut latest_state);
        let in_contact = latest_state.as_ref().unwrap().in_contact;
        approached |= !in_contact;
        if approached && in_contact {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "no contact again in 10 s");
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(300));
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["force", &last.to_string(), "--duration", "2", "--tolerance", "0.05"])
        .output()
        .unwrap();
    eprint!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{last} N not reached within 5 % after the re-tare");

    same_goal_id_twice(&mut node, last);
}

/// A client that resends its goal while the reply is late (the Fast DDS and Cyclone DDS peers do) or a
/// replay of the request: the same goal id, sent again while its press runs and after it ended, is
/// answered as it first was and starts nothing — the press is neither superseded nor restarted.
fn same_goal_id_twice(node: &mut ros2_client::Node, force: f64) {
    use ros2_client::action::{ActionClientQosPolicies, GoalId, GoalStatusEnum, SendGoalRequest};
    use softcontact_msgs::softcontact_msgs::{PressForceFeedback, PressForceGoal, PressForceResult};
    let [goal_service, result_service, cancel_service, feedback_subscription, status_subscription] =
        ros::press_action_qos();
    let qos = ActionClientQosPolicies {
        goal_service,
        result_service,
        cancel_service,
        feedback_subscription,
        status_subscription,
    };
    let press = node
        .create_action_client::<PressForceGoal, PressForceResult, PressForceFeedback>(
            ros::service_mapping("cyclone").unwrap(),
            &Name::new("/deformation_controller", "press").unwrap(),
            &ros2_client::ActionTypeName::new("softcontact_msgs", "PressForce"),
            qos,
        )
        .unwrap();
    std::thread::sleep(Duration::from_millis(500)); // discovery
    let request = SendGoalRequest { goal_id: GoalId::new_random(), goal: PressForceGoal { force, duration: 2.0 } };
    let accepted = |press: &ros2_client::action::ActionClient<_, _, _>| {
        let id = press.goal_client().send_request(request.clone()).unwrap();
        let start = Instant::now();
        loop {
            if let Ok(Some(r)) = press.receive_goal_response(id) {
                return r.accepted;
            }
            assert!(start.elapsed() < Duration::from_secs(3), "no answer to the goal in 3 s");
            std::thread::sleep(Duration::from_millis(2));
        }
    };
    let sent = Instant::now();
    assert!(accepted(&press), "the goal accepted");
    std::thread::sleep(Duration::from_millis(700));
    assert!(accepted(&press), "the same goal id, sent again while it runs, answered as before");
    let result = |press: &ros2_client::action::ActionClient<_, _, _>| {
        let id = press.request_result(request.goal_id).unwrap();
        let start = Instant::now();
        loop {
            if let Ok(Some((status, r))) = press.receive_result(id) {
                return (status, r);
            }
            assert!(start.elapsed() < Duration::from_secs(6), "no result in 6 s");
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let (status, r): (GoalStatusEnum, PressForceResult) = result(&press);
    let took = sent.elapsed().as_secs_f64();
    eprintln!("same goal id twice: {status:?} after {took:.2} s: {:.2} N, {}", r.force, r.message);
    assert_eq!(status, GoalStatusEnum::Succeeded, "{}", r.message);
    // Restarted by the resend, the 2 s press would end 0.7 s later.
    assert!(took < 2.5, "the press ended {took:.2} s after it was sent (2 s long)");
    assert!(accepted(&press), "the ended goal's id, sent again, answered as before");
    // A press started by the replay would show in the status list as executing.
    std::thread::sleep(Duration::from_millis(300));
    let mut executing = false;
    while let Ok(Some(statuses)) = press.receive_status() {
        executing = statuses
            .status_list
            .iter()
            .any(|s| s.goal_info.goal_id == request.goal_id && s.status == GoalStatusEnum::Executing);
    }
    assert!(!executing, "the replayed goal id started a press");
    let (status, again) = result(&press);
    assert_eq!((status, again.message), (GoalStatusEnum::Succeeded, r.message), "the replay left the result as it was");
}
