//! The real graph, as users start it: `launch-scripts/sim.sh --isolated` brings up sim_arm and the four
//! nodes over DDS in a network namespace with only loopback, and this test runs inside it as a user
//! would: it waits for contact, has the controller push the sponge at 1 Hz while the estimator learns
//! it, checks the learned model against the simulator's surface, sends 5 force commands with the
//! `softcontact force` command and checks each is reached within 5 %, and lets a Cyclone DDS peer
//! (Python) read two topics. Outside, it checks that every process stopped cleanly, that the driver
//! answered the KRC within 200 µs in ≥ 99.9 % of cycles, and each node's peak memory.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use softcontact_msgs::softcontact_msgs::{ContactModel, ControllerState, ForceCommand};
use softcontact_nodes::ros;

const INSIDE: &str = "SOFTCONTACT_GRAPH_CLIENT";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

#[test]
fn the_graph_reaches_force_commands_on_the_sponge() {
    if std::env::var(INSIDE).is_ok() {
        return client();
    }
    let logs = std::env::temp_dir().join(format!("softcontact-graph-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&logs);
    let bin = Path::new(env!("CARGO_BIN_EXE_softcontact")).parent().unwrap();
    let out = Command::new(root().join("launch-scripts/sim.sh"))
        .args(["--isolated", "--log-dir"])
        .arg(&logs)
        .arg("--run")
        .arg(std::env::current_exe().unwrap())
        .args(["--exact", "the_graph_reaches_force_commands_on_the_sponge", "--nocapture", "--test-threads=1"])
        .env(INSIDE, "1")
        .env("SOFTCONTACT_BIN", bin)
        .output()
        .expect("sim.sh runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    eprintln!("{text}");
    assert!(out.status.success(), "the graph run failed (logs in {})", logs.display());
    assert!(text.contains("1 passed"), "the client ran and passed");

    let log = |n: &str| std::fs::read_to_string(logs.join(format!("{n}.log"))).unwrap();
    for n in ["sim_arm", "lwr_driver", "ft_sensor", "contact_estimator", "deformation_controller"] {
        let l = log(n);
        assert!(l.contains("exit"), "{n} wrote its exit report:\n{l}");
        let rss: f64 = number_after(&l, "peak RSS ").unwrap_or_else(|| panic!("{n} reports its memory"));
        assert!(rss < 30.0, "{n}: peak RSS {rss} MB (goal < 30 MB)");
    }
    let driver = log("lwr_driver");
    let within = number_after(&driver, "within 200 us: ").expect("reply latency reported");
    assert!(within >= 99.9, "FRI answers within 200 us in {within} % of cycles");
    let _ = std::fs::remove_dir_all(&logs);
}

/// The number that follows `key` in `text` (its last occurrence).
fn number_after(text: &str, key: &str) -> Option<f64> {
    let rest = &text[text.rfind(key)? + key.len()..];
    rest.split(|c: char| !(c.is_ascii_digit() || c == '.')).next()?.parse().ok()
}

/// Inside the namespace, with the graph up.
fn client() {
    let mut node = ros::node("graph_test").unwrap();
    let states =
        ros::subscription::<ControllerState>(&mut node, "/deformation_controller/state", ros::sensor_qos()).unwrap();
    let models = ros::subscription::<ContactModel>(&mut node, "/contact_estimator/model", ros::reliable_qos()).unwrap();
    let commands =
        ros::publisher::<ForceCommand>(&mut node, "/deformation_controller/force_command", ros::reliable_qos())
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

    // Identification pushes at 1 Hz (seed 001), until the window is full; the controller adopts the
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
    let m = latest_model.unwrap();
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

    // A peer on another DDS implementation reads the wrench and the controller state at the last hold.
    let out = Command::new("python3")
        .arg(root().join("tests/interop_cyclonedds.py"))
        .arg(last.to_string())
        .output()
        .expect("python3 runs");
    eprint!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "the Cyclone DDS peer decoded both topics");
}
