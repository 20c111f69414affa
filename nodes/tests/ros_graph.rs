//! The driver nodes as ROS 2 processes over real DDS, against `sim_arm` over real UDP. DDS stays on this
//! machine: the test re-runs itself inside a network namespace that has only loopback (design.md
//! section 3), where it starts the three node processes and talks to them as a controller would.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use ros2_client::{Name, ServiceTypeName};
use softcontact_dynamics::lwr4;
use softcontact_msgs::diagnostic_msgs::DiagnosticArray;
use softcontact_msgs::geometry_msgs::{PoseStamped, WrenchStamped};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use softcontact_nodes::ros;

const INNER: &str = "SOFTCONTACT_INSIDE_NETNS";

/// Runs the named test of this binary again, inside a fresh network namespace with only `lo` (in a user
/// namespace too, so that it needs no root).
fn in_isolated_namespace(test: &str) {
    let exe = std::env::current_exe().unwrap();
    let script = format!(
        "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && exec '{}' --exact {test} --nocapture --test-threads=1",
        exe.display()
    );
    let out = Command::new("unshare")
        .args(["--map-root-user", "--net", "sh", "-c", &script])
        .env(INNER, "1")
        .output()
        .expect("unshare runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    eprintln!("{text}");
    assert!(out.status.success() && text.contains("1 passed"), "isolated run failed:\n{text}");
}

struct Processes(Vec<Child>);

impl Drop for Processes {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn spawn(bin: &str, args: &[&str]) -> Child {
    Command::new(bin).args(args).stdin(Stdio::null()).spawn().unwrap_or_else(|e| panic!("{bin}: {e}"))
}

#[test]
fn driver_and_ft_nodes_serve_the_graph_over_dds() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("driver_and_ft_nodes_serve_the_graph_over_dds");
        return;
    }
    let mut node = ros::node("graph_test").unwrap();
    let joints = ros::subscription::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos()).unwrap();
    let poses = ros::subscription::<PoseStamped>(&mut node, "/lwr/ee_pose", ros::sensor_qos()).unwrap();
    let wrenches = ros::subscription::<WrenchStamped>(&mut node, "/ft_sensor/wrench", ros::sensor_qos()).unwrap();
    let diagnostics = ros::subscription::<DiagnosticArray>(&mut node, "/diagnostics", ros::reliable_qos()).unwrap();
    let torque = ros::publisher::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos()).unwrap();
    let bias = node
        .create_client::<TriggerRequest, TriggerResponse>(
            ros::service_mapping("cyclone").unwrap(),
            &Name::new("/ft_sensor", "bias").unwrap(),
            &ServiceTypeName::new("std_srvs", "Trigger"),
            ros::reliable_qos(),
            ros::reliable_qos(),
        )
        .unwrap();

    let _procs = Processes(vec![
        spawn(env!("CARGO_BIN_EXE_sim_arm"), &["-p", "surface:=dice", "-p", "seconds:=8"]),
        spawn(env!("CARGO_BIN_EXE_lwr_driver"), &["-p", "exit_after_silence:=1"]),
        spawn(env!("CARGO_BIN_EXE_ft_sensor"), &["-p", "exit_after_silence:=1", "-p", "tare_after:=-1"]),
    ]);

    let model = lwr4::model();
    let mut data = model.data();
    let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
    let start = Instant::now();
    let (mut n_joints, mut n_poses, mut n_wrenches) = (0usize, 0usize, 0usize);
    let mut first_q: Option<Vec<f64>> = None;
    let mut last_q = Vec::new();
    let mut pose_error: f64 = 0.0;
    let mut last_wrench = None;
    let mut driver_diag = None;
    let mut bias_answer = None;
    let mut bias_sent = false;
    while start.elapsed() < Duration::from_secs(7) {
        while let Ok(Some((js, _))) = joints.take() {
            assert_eq!(js.name.len(), 7);
            assert_eq!(js.name[2], "lwr_e1_joint");
            n_joints += 1;
            // The controller's part: hold the arm with exactly the gravity torque.
            let g = model.gravity_torques(&mut data, &js.position).as_slice().to_vec();
            torque.publish(JointState { effort: g, ..Default::default() }).unwrap();
            if n_joints > 2000 && first_q.is_none() {
                first_q = Some(js.position.clone());
            }
            last_q = js.position;
        }
        while let Ok(Some((p, _))) = poses.take() {
            n_poses += 1;
            if last_q.len() == 7 && n_poses > 2000 {
                model.forward_kinematics(&mut data, &last_q);
                let fk = model.frame_pose(&data, tool).translation.vector;
                let pos = p.pose.position;
                pose_error = pose_error.max((fk - nalgebra::Vector3::new(pos.x, pos.y, pos.z)).norm());
            }
        }
        while let Ok(Some((w, _))) = wrenches.take() {
            n_wrenches += 1;
            assert_eq!(w.header.frame_id, "ft_sensor");
            last_wrench = Some(w.wrench);
        }
        while let Ok(Some((d, _))) = diagnostics.take() {
            for s in d.status {
                if s.name.starts_with("lwr_driver") && n_joints > 1000 {
                    driver_diag = Some(s);
                }
            }
        }
        if !bias_sent && n_wrenches > 500 {
            bias.send_request(TriggerRequest::default()).unwrap();
            bias_sent = true;
        }
        if bias_sent && bias_answer.is_none() {
            while let Ok(Some((_, r))) = bias.receive_response() {
                bias_answer = Some(r);
            }
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    eprintln!("received {n_joints} joint states, {n_poses} poses, {n_wrenches} wrenches in 7 s");
    assert!(n_joints > 3000, "joint states at ~1 kHz: {n_joints}");
    assert!(n_poses > 3000 && n_wrenches > 3000, "poses {n_poses}, wrenches {n_wrenches}");
    let drift = first_q.unwrap().iter().zip(&last_q).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(drift < 2e-3, "held by its gravity torque over DDS: drift {drift} rad");
    assert!(pose_error < 2e-3, "ee_pose agrees with FK of joint_states: {pose_error} m");
    // Hand in the air, tool weight compensated and (after the tare) bias removed: little force left.
    let w = last_wrench.unwrap();
    assert!(w.force.z.abs() < 0.5 && w.force.x.abs() < 0.5, "{w:?}");
    let answer = bias_answer.expect("/ft_sensor/bias answered");
    assert!(answer.success, "{answer:?}");
    let d = driver_diag.expect("driver diagnostics");
    assert!(d.values.iter().any(|kv| kv.key == "lost"), "{d:?}");
}

#[test]
fn lockstep_runs_faster_than_real_time_on_sim_time() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("lockstep_runs_faster_than_real_time_on_sim_time");
        return;
    }
    use softcontact_msgs::rosgraph_msgs::Clock;
    let mut node = ros::node("lockstep_test").unwrap();
    let clock = ros::subscription::<Clock>(&mut node, "/clock", ros::reliable_qos()).unwrap();
    let joints = ros::subscription::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos()).unwrap();
    let mut driver =
        spawn(env!("CARGO_BIN_EXE_lwr_driver"), &["-p", "use_sim_time:=true", "-p", "exit_after_silence:=1"]);
    std::thread::sleep(Duration::from_millis(500)); // discovery
    let start = Instant::now();
    let mut sim =
        spawn(env!("CARGO_BIN_EXE_sim_arm"), &["-p", "lockstep:=true", "-p", "surface:=none", "-p", "seconds:=10"]);
    let (mut latest_clock, mut latest_stamp, mut stamps) = (0.0f64, 0.0f64, 0usize);
    let status = loop {
        while let Ok(Some((c, _))) = clock.take() {
            latest_clock = latest_clock.max(c.clock.as_secs_f64());
        }
        while let Ok(Some((js, _))) = joints.take() {
            latest_stamp = js.header.stamp.as_secs_f64();
            stamps += 1;
        }
        if let Some(status) = sim.try_wait().unwrap() {
            break status;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "lockstep run did not finish");
        std::thread::sleep(Duration::from_micros(500));
    };
    let wall = start.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(200));
    while let Ok(Some((c, _))) = clock.take() {
        latest_clock = latest_clock.max(c.clock.as_secs_f64());
    }
    let _ = driver.kill();
    let _ = driver.wait();
    eprintln!(
        "lockstep: 10 simulated s in {wall:.2} s wall; /clock reached {latest_clock:.3} s; {stamps} joint states"
    );
    assert!(status.success());
    assert!(wall < 10.0, "faster than real time: {wall} s of wall time for 10 s");
    assert!(latest_clock > 9.9, "/clock advanced to the end: {latest_clock}");
    assert!(
        stamps > 1000 && latest_stamp > 1.0 && latest_stamp <= 10.01,
        "joint states stamped in sim time: {latest_stamp}"
    );
}
