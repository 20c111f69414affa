//! Recordings as hostile input to the `softcontact` command: replay never publishes commands to the arm
//! unless asked, keeps its timing whatever a summary says, refuses absurd --rate and --wait without a
//! panic; identify and model refuse devices and oversized files at once. Every replay runs in a network
//! namespace with loopback only (its DDS traffic reaches nothing else).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use softcontact_bag::{AnyMessage, BagWriter, Qos};
use softcontact_msgs::geometry_msgs::{Vector3, Wrench, WrenchStamped};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{ContactModel, ForceCommand};
use softcontact_nodes::runtime::ros;

const INNER: &str = "SOFTCONTACT_RECORDINGS_TEST_INNER";
const T0: u64 = 1_700_000_000_000_000_000;

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// Runs `command` to its end or for `limit`, then kills it; the output and whether it ended in time.
fn run_for(mut command: Command, limit: Duration) -> (Output, bool) {
    let mut child = command.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("runs");
    let start = Instant::now();
    let mut ended = true;
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            ended = false;
            child.kill().unwrap();
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    (child.wait_with_output().unwrap(), ended)
}

/// `softcontact ARGS` in a fresh user and network namespace whose only interface is loopback.
fn isolated(args: &[&str]) -> Command {
    let mut c = Command::new("unshare");
    c.args(["--map-root-user", "--net", "sh", "-c"])
        .arg(
            "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && exec \"$0\" \"$@\"",
        )
        .arg(env!("CARGO_BIN_EXE_softcontact"))
        .args(args);
    c
}

fn softcontact(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_softcontact"));
    c.args(args);
    c
}

fn wrench(i: u32) -> WrenchStamped {
    WrenchStamped {
        wrench: Wrench { force: Vector3 { x: 0.0, y: 0.0, z: -10.0 - i as f64 }, ..Default::default() },
        ..Default::default()
    }
}

/// 50 rounds, 20 ms apart, of commands to the arm and sensor readings.
fn write_commands(path: &Path) {
    let mut w = BagWriter::create(path).unwrap();
    for i in 0..50u32 {
        let t = T0 + i as u64 * 20_000_000;
        let torque = AnyMessage::JointState(JointState { effort: vec![5.0; 7], ..Default::default() });
        torque.write(&mut w, "/lwr/joint_torque_command", Qos::RELIABLE, t).unwrap();
        let force = AnyMessage::ForceCommand(ForceCommand { force: 100.0, duration: 0.5 });
        force.write(&mut w, "/deformation_controller/force_command", Qos::RELIABLE, t).unwrap();
        let model = AnyMessage::ContactModel(ContactModel { stiffness: 1e5, ..Default::default() });
        model.write(&mut w, "/contact_estimator/model", Qos::RELIABLE, t).unwrap();
        AnyMessage::WrenchStamped(wrench(i)).write(&mut w, "/ft_sensor/wrench", Qos::RELIABLE, t).unwrap();
    }
    w.finish().unwrap();
}

fn dir() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("recordings-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn replay_refuses_absurd_rate_and_wait_with_a_message_not_a_panic() {
    let path = dir().join("rate.mcap");
    let _ = std::fs::remove_file(&path);
    write_commands(&path);
    let file = path.to_str().unwrap();
    for (option, value) in [
        ("--wait", "inf"),
        ("--wait", "1e300"),
        ("--wait", "NaN"),
        ("--wait", "-1"),
        ("--wait", "3601"),
        ("--rate", "1e-300"),
        ("--rate", "1e300"),
        ("--rate", "NaN"),
        ("--rate", "inf"),
        ("--rate", "0"),
        ("--rate", "-2"),
    ] {
        let (o, ended) = run_for(
            isolated(&["replay", file, "--topics", "/ft_sensor/wrench", &format!("{option}={value}")]),
            Duration::from_secs(10),
        );
        let t = text(&o);
        assert!(ended, "{option} {value}: still running after 10 s:\n{t}");
        assert!(!o.status.success() && o.status.code() != Some(101), "{option} {value}: {:?}\n{t}", o.status);
        assert!(!t.contains("panicked"), "{option} {value}:\n{t}");
        let range = if option == "--rate" { "between 0.01 and 100" } else { "between 0 and 3600 s" };
        assert!(t.contains(&format!("{option} must be {range}")), "{option} {value}:\n{t}");
    }
}

/// The recording of `write_commands` with its summary's start time moved after its first message
/// (footer CRC zeroed: "not computed", as MCAP allows).
fn with_late_summary_start(from: &Path, to: &Path) {
    let mut bytes = std::fs::read(from).unwrap();
    let footer = bytes.len() - 8 - 29;
    let summary_start = u64::from_le_bytes(bytes[footer + 9..footer + 17].try_into().unwrap()) as usize;
    bytes[footer + 25..footer + 29].fill(0);
    let mut at = summary_start;
    while bytes[at] != 0x0b {
        at += 9 + u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
    }
    // Statistics: count u64, schema u16, channel u32, attachment u32, metadata u32, chunk u32, start u64
    let start = at + 9 + 8 + 2 + 4 + 4 + 4 + 4;
    assert_eq!(u64::from_le_bytes(bytes[start..start + 8].try_into().unwrap()), T0);
    bytes[start..start + 8].copy_from_slice(&(T0 + 500_000_000).to_le_bytes());
    std::fs::write(to, bytes).unwrap();
}

#[test]
fn replay_times_from_the_first_message_whatever_the_summary_says() {
    let d = dir();
    let (path, late) = (d.join("origin.mcap"), d.join("late.mcap"));
    let _ = std::fs::remove_file(&path);
    write_commands(&path);
    with_late_summary_start(&path, &late);
    let (o, ended) = run_for(
        isolated(&["replay", late.to_str().unwrap(), "--topics", "/ft_sensor/wrench", "--wait", "0"]),
        Duration::from_secs(15),
    );
    let t = text(&o);
    assert!(ended, "replay of 1 s of recording still running after 15 s:\n{t}");
    assert!(o.status.success() && t.contains("replayed 50 messages"), "{t}");
}

#[test]
fn replay_never_publishes_commands_to_the_arm_unless_asked() {
    if std::env::var(INNER).is_ok() {
        return commands_inside();
    }
    let exe = std::env::current_exe().unwrap();
    let mut c = Command::new("unshare");
    c.args(["--map-root-user", "--net", "sh", "-c"])
        .arg(
            "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && exec \"$0\" \
             --exact replay_never_publishes_commands_to_the_arm_unless_asked --nocapture --test-threads=1",
        )
        .arg(exe)
        .env(INNER, "1");
    let (o, ended) = run_for(c, Duration::from_secs(120));
    let t = text(&o);
    eprintln!("{t}");
    assert!(ended && o.status.success() && t.contains("1 passed"), "isolated run failed:\n{t}");
}

/// Inside the namespace: a subscriber on every topic of the recording counts what replay publishes.
fn commands_inside() {
    let path = dir().join("commands.mcap");
    let _ = std::fs::remove_file(&path);
    write_commands(&path);
    let file = path.to_str().unwrap();
    let mut node = ros::node("replay_safety_test").unwrap();
    let qos = ros::reliable_qos();
    let torques = ros::subscription_by_name::<JointState>(&mut node, "/lwr/joint_torque_command", qos.clone()).unwrap();
    let forces =
        ros::subscription_by_name::<ForceCommand>(&mut node, "/deformation_controller/force_command", qos.clone())
            .unwrap();
    let models = ros::subscription_by_name::<ContactModel>(&mut node, "/contact_estimator/model", qos.clone()).unwrap();
    let wrenches = ros::subscription_by_name::<WrenchStamped>(&mut node, "/ft_sensor/wrench", qos).unwrap();
    let replay = |extra: &[&str]| {
        let mut child = softcontact(&[&["replay", file, "--wait", "2"][..], extra].concat())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Taken while replay runs and for a second after it.
        let mut counts = [0; 4];
        let mut ended = None;
        while ended.is_none_or(|t: Instant| t.elapsed() < Duration::from_secs(1)) {
            if ended.is_none() && child.try_wait().unwrap().is_some() {
                ended = Some(Instant::now());
            }
            while let Ok(Some(_)) = torques.take() {
                counts[0] += 1;
            }
            while let Ok(Some(_)) = forces.take() {
                counts[1] += 1;
            }
            while let Ok(Some(_)) = models.take() {
                counts[2] += 1;
            }
            while let Ok(Some(_)) = wrenches.take() {
                counts[3] += 1;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let o = child.wait_with_output().unwrap();
        let t = text(&o);
        eprintln!("{t}\nreceived {counts:?}");
        (o.status.success(), t, counts)
    };

    // By default: the sensor readings, none of the commands; it says which it skipped and why.
    let (ok, t, [torque, force, model, wrench]) = replay(&[]);
    assert!(ok, "{t}");
    assert!(wrench > 0, "the subscriber hears replay ({wrench} wrenches)");
    assert_eq!((torque, force, model), (0, 0, 0), "commands to the arm published by default");
    for topic in ["/lwr/joint_torque_command", "/deformation_controller/force_command", "/contact_estimator/model"] {
        assert!(t.contains(&format!("skipping {topic} (")) && !t.contains(&format!("replaying {topic}")), "{t}");
    }
    assert!(t.contains("it commands the arm (the driver applies them to the arm); --actuators replays it"), "{t}");

    // Named without --actuators: refused, before anything is published.
    let (ok, t, counts) = replay(&["--topics", "/ft_sensor/wrench,/lwr/joint_torque_command"]);
    assert!(!ok && t.contains("/lwr/joint_torque_command commands the arm") && t.contains("add --actuators"), "{t}");
    assert_eq!(counts, [0; 4], "nothing published when refused");

    // Asked for explicitly: published, and said so.
    let (ok, t, [torque, force, model, _]) = replay(&["--actuators"]);
    assert!(
        ok && t.contains(
            "replaying /lwr/joint_torque_command (sensor_msgs/msg/JointState, 50 messages, commands to the arm)"
        ),
        "{t}"
    );
    assert!(torque > 0 && force > 0 && model > 0, "--actuators: {torque} torques, {force} forces, {model} models");
}

#[test]
fn identify_and_model_refuse_devices_and_oversized_files_at_once() {
    let big = dir().join("big.urdf");
    std::fs::write(&big, vec![b' '; 5 << 20]).unwrap();
    let big = big.to_str().unwrap();
    for (args, words) in [
        (&["identify", "/dev/zero"][..], "/dev/zero: not a regular file"),
        (&["model", "--urdf", "/dev/zero"], "not a regular file"),
        (&["model", "--urdf", big], "larger than 4 MB"),
    ] {
        let start = Instant::now();
        let (o, ended) = run_for(softcontact(args), Duration::from_secs(5));
        let t = text(&o);
        assert!(ended, "{args:?}: still running after 5 s");
        assert!(!o.status.success() && t.contains(words), "{args:?} in {:?}:\n{t}", start.elapsed());
    }
}
