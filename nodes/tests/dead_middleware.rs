//! A dead middleware is noticed by every node: no traffic where traffic is due. The graph's node
//! processes run in a network namespace with only loopback; the driver is stopped for good (SIGSTOP: its
//! DDS goes silent, as a dead participant's does). The estimator and the controller must exit non-zero
//! within `dead_after` and a margin, each naming the stream that went silent, so that the launch script
//! stops the graph. Then the driver is continued with its controller gone: it must hold the arm, keep
//! running while the KRC commands, and report the silent command stream as ERROR on /diagnostics.

#[allow(dead_code)]
mod common;

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use common::{INNER, in_isolated_namespace};
use softcontact_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{ContactState, ControllerState};
use softcontact_nodes::runtime::ros;

/// The nodes' `dead_after` in this test [s], and how late past it a node may notice.
const DEAD_AFTER: f64 = 1.0;
const MARGIN: f64 = 1.0;

/// The node processes, each logging to a file; killed (and continued first, if stopped) on drop.
struct Processes {
    logs: PathBuf,
    children: Vec<(&'static str, Child)>,
}

impl Processes {
    fn spawn(&mut self, name: &'static str, bin: &str, args: &[&str]) {
        let log = File::create(self.log_path(name)).unwrap();
        let child = Command::new(bin)
            .args(args)
            .stdin(Stdio::null())
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .unwrap_or_else(|e| panic!("{bin}: {e}"));
        self.children.push((name, child));
    }

    fn log_path(&self, name: &str) -> PathBuf {
        self.logs.join(format!("{name}.log"))
    }

    fn log(&self, name: &str) -> String {
        std::fs::read_to_string(self.log_path(name)).unwrap_or_default()
    }

    fn child(&mut self, name: &str) -> &mut Child {
        &mut self.children.iter_mut().find(|(n, _)| *n == name).unwrap().1
    }

    fn signal(&mut self, name: &str, sig: libc::c_int) {
        let pid = self.child(name).id() as libc::pid_t;
        // SAFETY: kill(2) on the pid of a child we have not waited for yet.
        assert_eq!(unsafe { libc::kill(pid, sig) }, 0, "kill {sig} {name}");
    }

    fn exited(&mut self, name: &str) -> Option<ExitStatus> {
        self.child(name).try_wait().unwrap()
    }
}

impl Drop for Processes {
    fn drop(&mut self) {
        for (_, c) in &mut self.children {
            if let Ok(None) = c.try_wait() {
                // SAFETY: as above (not reaped yet); a stopped child is continued so that it is reaped.
                unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGCONT) };
            }
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn drain<T: serde::de::DeserializeOwned + 'static>(s: &ros2_client::Subscription<T>) -> usize {
    let mut n = 0;
    while let Ok(Some(_)) = s.take() {
        n += 1;
    }
    n
}

/// Messages received in `window`, read often (the sensor QoS keeps only the newest).
fn count<T: serde::de::DeserializeOwned + 'static>(s: &ros2_client::Subscription<T>, window: Duration) -> usize {
    let (end, mut n) = (Instant::now() + window, 0);
    while Instant::now() < end {
        n += drain(s);
        std::thread::sleep(Duration::from_micros(500));
    }
    n
}

#[test]
fn nodes_notice_a_dead_middleware() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("nodes_notice_a_dead_middleware");
        return;
    }
    let logs = std::env::temp_dir().join(format!("softcontact-dead-middleware-{}", std::process::id()));
    std::fs::create_dir_all(&logs).unwrap();
    let mut node = ros::node("dead_middleware_test").unwrap();
    let joint_states =
        ros::subscription_by_name::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos()).unwrap();
    let estimator_states =
        ros::subscription_by_name::<ContactState>(&mut node, "/contact_estimator/state", ros::sensor_qos()).unwrap();
    let controller_states =
        ros::subscription_by_name::<ControllerState>(&mut node, "/deformation_controller/state", ros::sensor_qos())
            .unwrap();
    let diagnostics =
        ros::subscription_by_name::<DiagnosticArray>(&mut node, "/diagnostics", ros::reliable_qos()).unwrap();

    let dead_after = format!("dead_after:={DEAD_AFTER}");
    let mut procs = Processes { logs: logs.clone(), children: Vec::new() };
    procs.spawn("sim_arm", &common::workspace_binary("sim_arm"), &["-p", "surface:=dice", "-p", "seconds:=60"]);
    procs.spawn("lwr_driver", env!("CARGO_BIN_EXE_lwr_driver"), &["-p", &dead_after]);
    procs.spawn("ft_sensor", env!("CARGO_BIN_EXE_ft_sensor"), &["-p", &dead_after]);
    procs.spawn("contact_estimator", env!("CARGO_BIN_EXE_contact_estimator"), &["-p", &dead_after]);
    procs.spawn("deformation_controller", env!("CARGO_BIN_EXE_deformation_controller"), &["-p", &dead_after]);

    // Up: the driver publishing, the estimator and the controller receiving and publishing (the
    // controller ticks only with fresh wrenches, so the F/T node is up and tared too).
    let start = Instant::now();
    let (mut js, mut est, mut ctl) = (0, 0, 0);
    while js < 2000 || est < 50 || ctl < 50 {
        std::thread::sleep(Duration::from_millis(20));
        js += drain(&joint_states);
        est += drain(&estimator_states);
        ctl += drain(&controller_states);
        drain(&diagnostics);
        for name in ["lwr_driver", "contact_estimator", "deformation_controller"] {
            assert!(procs.exited(name).is_none(), "{name} exited while coming up:\n{}", procs.log(name));
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "graph did not come up: {js} joint states, {est} estimator states, {ctl} controller states"
        );
    }
    eprintln!(
        "up after {:.1} s: {js} joint states, {est} estimator states, {ctl} controller states",
        start.elapsed().as_secs_f64()
    );
    // The controller commands the arm for a while, so that the driver has seen its commands flow.
    std::thread::sleep(Duration::from_millis(500));

    // The driver's DDS stops for good: joint states and poses are silent from now on.
    procs.signal("lwr_driver", libc::SIGSTOP);
    let stopped = Instant::now();
    let mut exits: Vec<(&str, f64, ExitStatus)> = Vec::new();
    let mut ft_reported = None;
    while (exits.len() < 2 || ft_reported.is_none()) && stopped.elapsed().as_secs_f64() < DEAD_AFTER + MARGIN + 2.0 {
        // The F/T node cannot compensate the hand's weight without poses: it withholds and reports.
        while let Ok(Some((d, _))) = diagnostics.take() {
            for s in d.status {
                if s.name.starts_with("ft_sensor")
                    && s.level == DiagnosticStatus::ERROR
                    && s.message.contains("/lwr/ee_pose")
                    && ft_reported.is_none()
                {
                    ft_reported = Some((stopped.elapsed().as_secs_f64(), s.message));
                }
            }
        }
        for name in ["contact_estimator", "deformation_controller"] {
            if !exits.iter().any(|(n, _, _)| *n == name)
                && let Some(status) = procs.exited(name)
            {
                exits.push((name, stopped.elapsed().as_secs_f64(), status));
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    for (name, stream) in [("contact_estimator", "/lwr/ee_pose"), ("deformation_controller", "/lwr/joint_states")] {
        let log = procs.log(name);
        let Some((_, after, status)) = exits.iter().find(|(n, _, _)| *n == name) else {
            panic!("{name} still runs {:.1} s after the driver stopped:\n{log}", stopped.elapsed().as_secs_f64());
        };
        eprintln!("{name}: exited {after:.2} s after the driver stopped, {status}");
        assert!(!status.success(), "{name} exits with an error: {status}\n{log}");
        assert!(
            *after >= DEAD_AFTER - 0.05 && *after <= DEAD_AFTER + MARGIN,
            "{name} exited {after:.2} s after the driver stopped (dead_after {DEAD_AFTER} s)\n{log}"
        );
        let line =
            log.lines().find(|l| l.contains("no message for")).unwrap_or_else(|| panic!("{name} says why:\n{log}"));
        eprintln!("{name}: {line}");
        assert!(line.contains(stream), "{name} names {stream}: {line}");
    }

    let (after, message) = ft_reported.unwrap_or_else(|| {
        panic!("the F/T node reports the silent poses on /diagnostics:\n{}", procs.log("ft_sensor"))
    });
    eprintln!("ft_sensor: /diagnostics ERROR {after:.2} s after the driver stopped: {message}");
    assert!(after >= DEAD_AFTER - 0.05, "ft_sensor reported {after:.2} s after, dead_after {DEAD_AFTER} s");
    assert!(procs.exited("ft_sensor").is_none(), "the F/T node never exits for it:\n{}", procs.log("ft_sensor"));

    // The driver again, its controller gone: the KRC still commands, the driver holds and reports.
    drain(&diagnostics);
    procs.signal("lwr_driver", libc::SIGCONT);
    let continued = Instant::now();
    let mut reported = None;
    while reported.is_none() && continued.elapsed() < Duration::from_secs(10) {
        while let Ok(Some((d, _))) = diagnostics.take() {
            for s in d.status {
                if s.name.starts_with("lwr_driver")
                    && s.level == DiagnosticStatus::ERROR
                    && s.message.contains("/lwr/joint_torque_command")
                {
                    reported = Some((continued.elapsed().as_secs_f64(), s.message));
                }
            }
        }
        drain(&joint_states);
        std::thread::sleep(Duration::from_millis(20));
    }
    let driver_log = |p: &Processes| p.log("lwr_driver");
    let (after, message) = reported
        .unwrap_or_else(|| panic!("the driver reports the silent commands on /diagnostics:\n{}", driver_log(&procs)));
    eprintln!("lwr_driver: /diagnostics ERROR {after:.2} s after it continued: {message}");
    count(&joint_states, Duration::from_secs(1));
    let flowing = count(&joint_states, Duration::from_secs(1));
    assert!(procs.exited("lwr_driver").is_none(), "the driver never exits for it:\n{}", driver_log(&procs));
    assert!(flowing > 500, "the driver answers the KRC and publishes: {flowing} joint states in 1 s");
    let log = driver_log(&procs);
    assert_eq!(
        log.lines().filter(|l| l.contains("no message for") && l.contains("/lwr/joint_torque_command")).count(),
        1,
        "the driver logs the silent commands once:\n{log}"
    );
    let _ = std::fs::remove_dir_all(Path::new(&logs));
}
