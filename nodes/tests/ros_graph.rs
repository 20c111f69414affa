//! The driver nodes as ROS 2 processes over real DDS, against `sim_arm` over real UDP. DDS stays on this
//! machine: the test re-runs itself inside a network namespace that has only loopback (docs/developing.md), where it starts the three node processes and talks to them as a controller would.

#[allow(dead_code)]
mod common;

use std::time::{Duration, Instant};

use common::{INNER, Processes, in_isolated_namespace, spawn};
use ros2_client::{Name, ServiceTypeName};
use softcontact_dynamics::lwr4;
use softcontact_msgs::diagnostic_msgs::DiagnosticArray;
use softcontact_msgs::geometry_msgs::{PoseStamped, WrenchStamped};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use softcontact_msgs::tf2_msgs::TFMessage;
use softcontact_nodes::runtime::ros;

#[test]
fn driver_and_ft_nodes_serve_the_graph_over_dds() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("driver_and_ft_nodes_serve_the_graph_over_dds");
        return;
    }
    let mut node = ros::node("graph_test").unwrap();
    let joints = ros::subscription_by_name::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos()).unwrap();
    let poses = ros::subscription_by_name::<PoseStamped>(&mut node, "/lwr/ee_pose", ros::sensor_qos()).unwrap();
    let wrenches =
        ros::subscription_by_name::<WrenchStamped>(&mut node, "/ft_sensor/wrench", ros::sensor_qos()).unwrap();
    let diagnostics =
        ros::subscription_by_name::<DiagnosticArray>(&mut node, "/diagnostics", ros::reliable_qos()).unwrap();
    // As tf2's TransformListener (and rviz2, tf2_echo) reads /tf: reliable, keep-last 100.
    let tf2_listener_qos = ros::reliable_qos().history(ros2_client::qos::History::KeepLast { depth: 100 });
    let tf = ros::subscription_by_name::<TFMessage>(&mut node, "/tf", tf2_listener_qos).unwrap();
    let torque =
        ros::publisher_by_name::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos()).unwrap();
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
        spawn(&common::workspace_binary("sim_arm"), &["-p", "surface:=dice", "-p", "seconds:=8"]),
        spawn(env!("CARGO_BIN_EXE_lwr_driver"), &["-p", "exit_after_silence:=1"]),
        spawn(env!("CARGO_BIN_EXE_ft_sensor"), &["-p", "exit_after_silence:=1", "-p", "tare_after:=-1"]),
    ]);

    let model = lwr4::model();
    let mut data = model.data();
    let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
    let start = Instant::now();
    let (mut n_joints, mut n_poses, mut n_wrenches) = (0usize, 0usize, 0usize);
    let mut tf_stamps = Vec::new();
    let mut first_q: Option<Vec<f64>> = None;
    let mut last_q = Vec::new();
    let mut pose_error: f64 = 0.0;
    let mut last_wrench = None;
    let mut driver_diag = None;
    let mut bias_answer = None;
    let mut bias_sent = false;
    // A second writer of torque commands, joining once the first is pinned: well-formed commands for the
    // present session, in time, 20 N·m on joint 1 beyond gravity. Refused, they move nothing.
    let mut stranger: Option<(ros2_client::Node, ros2_client::Publisher<JointState>)> = None;
    while start.elapsed() < Duration::from_secs(7) {
        while let Ok(Some((js, _))) = joints.take() {
            assert_eq!(js.name.len(), 7);
            assert_eq!(js.name[2], "lwr_e1_joint");
            n_joints += 1;
            // The controller's part: gravity torques, for no session (refused, so the driver holds).
            let g = model.gravity_torques(&mut data, &js.position).as_slice().to_vec();
            if let Some((_, p)) = &stranger {
                let mut push = g.clone();
                push[0] += 20.0;
                p.publish(JointState { header: js.header.clone(), effort: push, ..Default::default() }).unwrap();
            }
            torque.publish(JointState { effort: g, ..Default::default() }).unwrap();
            if n_joints == 1500 {
                let mut node = ros::node("stranger").unwrap();
                let qos = ros::reliable_qos();
                let p = ros::publisher_by_name::<JointState>(&mut node, "/lwr/joint_torque_command", qos).unwrap();
                stranger = Some((node, p));
            }
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
        while let Ok(Some((t, _))) = tf.take() {
            assert_eq!(t.transforms.len(), 1);
            assert_eq!(
                (t.transforms[0].header.frame_id.as_str(), t.transforms[0].child_frame_id.as_str()),
                ("world", "lwr_tool")
            );
            tf_stamps.push((Instant::now(), t.transforms[0].header.stamp.as_secs_f64()));
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
    // /tf at most 100 Hz, to a reliable reader: over the last 4 s, 300 to 410 messages with rising stamps.
    let late: Vec<f64> =
        tf_stamps.iter().filter(|(at, _)| *at >= start + Duration::from_secs(3)).map(|(_, s)| *s).collect();
    eprintln!("/tf to a reliable keep-last-100 reader: {} messages, {} in the last 4 s", tf_stamps.len(), late.len());
    assert!((300..=410).contains(&late.len()), "/tf at ~100 Hz: {} in 4 s", late.len());
    assert!(late.windows(2).all(|w| w[1] > w[0]), "/tf stamps rise");
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
    let strangers = d.values.iter().find(|kv| kv.key == "commands_from_strangers").map(|kv| kv.value.clone());
    assert!(strangers.as_ref().and_then(|v| v.parse::<u64>().ok()).is_some_and(|n| n > 1000), "{d:?}");
    let faults = d.values.iter().filter(|kv| kv.key == "overspeed_cycles" || kv.key == "limit_cycles");
    assert!(faults.clone().all(|kv| kv.value == "0") && faults.count() == 2, "the stranger moved the arm: {d:?}");
}

#[test]
fn lockstep_runs_faster_than_real_time_on_sim_time() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("lockstep_runs_faster_than_real_time_on_sim_time");
        return;
    }
    use softcontact_msgs::rosgraph_msgs::Clock;
    let mut node = ros::node("lockstep_test").unwrap();
    let clock = ros::subscription_by_name::<Clock>(&mut node, "/clock", ros::clock_qos()).unwrap();
    let joints = ros::subscription_by_name::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos()).unwrap();
    let mut driver =
        spawn(env!("CARGO_BIN_EXE_lwr_driver"), &["-p", "use_sim_time:=true", "-p", "exit_after_silence:=1"]);
    std::thread::sleep(Duration::from_millis(500)); // discovery
    let start = Instant::now();
    let mut sim = spawn(
        &common::workspace_binary("sim_arm"),
        &["-p", "lockstep:=true", "-p", "surface:=none", "-p", "seconds:=10"],
    );
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

#[test]
fn a_namespaced_driver_serves_its_urdf_latched_and_joint_states_as_robot_state_publisher_reads_them() {
    // As docs/running.md sets it up for robot_state_publisher: /joint_states on, the driver's /tf off.
    use softcontact_msgs::std_msgs::String as Text;
    if std::env::var(INNER).is_err() {
        in_isolated_namespace(
            "a_namespaced_driver_serves_its_urdf_latched_and_joint_states_as_robot_state_publisher_reads_them",
        );
        return;
    }
    let mut node = ros::node("tools_test").unwrap();
    // robot_state_publisher's subscription: reliable, keep-last 10, volatile.
    let rsp_qos = ros::reliable_qos().history(ros2_client::qos::History::KeepLast { depth: 10 });
    let joint_states = ros::subscription_by_name::<JointState>(&mut node, "/cell2/joint_states", rsp_qos).unwrap();
    let moved =
        ros::subscription_by_name::<JointState>(&mut node, "/cell2/lwr/joint_states", ros::sensor_qos()).unwrap();
    let unmoved = ros::subscription_by_name::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos()).unwrap();
    let tf_qos = ros::reliable_qos().history(ros2_client::qos::History::KeepLast { depth: 100 });
    let tf = ros::subscription_by_name::<TFMessage>(&mut node, "/tf", tf_qos).unwrap();
    let args = [
        "--ros-args",
        "-r",
        "__ns:=/cell2",
        "-r",
        "__node:=arm_driver",
        "-p",
        "publish_joint_states:=true",
        "-p",
        "publish_tf:=false",
        "-p",
        "exit_after_silence:=1",
    ];
    let _procs = Processes(vec![
        spawn(&common::workspace_binary("sim_arm"), &["-p", "surface:=none", "-p", "seconds:=6"]),
        spawn(env!("CARGO_BIN_EXE_lwr_driver"), &args),
    ]);
    let (mut n_rsp, mut n_moved, mut n_unmoved, mut n_tf) = (0usize, 0usize, 0usize, 0usize);
    let start = Instant::now();
    let mut description: Option<String> = None;
    // A late joiner, as robot_state_publisher started after the driver: transient local hands it the URDF.
    let mut late: Option<ros2_client::Subscription<Text>> = None;
    while start.elapsed() < Duration::from_secs(5) {
        while let Ok(Some((js, _))) = joint_states.take() {
            assert_eq!(js.name.len(), 7);
            assert_eq!(js.position.len(), 7);
            n_rsp += 1;
        }
        while let Ok(Some(_)) = moved.take() {
            n_moved += 1;
        }
        while let Ok(Some(_)) = unmoved.take() {
            n_unmoved += 1;
        }
        while let Ok(Some(_)) = tf.take() {
            n_tf += 1;
        }
        if late.is_none() && start.elapsed() > Duration::from_secs(2) {
            late = Some(ros::subscription_by_name(&mut node, "/cell2/robot_description", ros::latched_qos()).unwrap());
        }
        if let Some(sub) = &late {
            while let Ok(Some((text, _))) = sub.take() {
                description = Some(text.data);
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    eprintln!(
        "/cell2/joint_states {n_rsp}, /cell2/lwr/joint_states {n_moved}, /lwr/joint_states {n_unmoved}, /tf {n_tf}"
    );
    assert_eq!(description.as_deref(), Some(lwr4::URDF), "the URDF the driver uses, to a late joiner");
    assert!((150..=520).contains(&n_rsp), "/joint_states at the /tf rate, reliable: {n_rsp} in 5 s");
    assert!(n_moved > 1500, "the 1 kHz joint states under the namespace: {n_moved}");
    assert_eq!(n_unmoved, 0, "nothing left under the name outside the namespace");
    assert_eq!(n_tf, 0, "robot_state_publisher publishes the tree: the driver's own /tf is off");
}

/// Calls a service until it answers (the server is discovered a little after the process starts).
fn call<Req: ros2_client::Message + Clone + 'static, Resp: ros2_client::Message + 'static>(
    client: &ros2_client::Client<Req, Resp>,
    request: Req,
) -> Resp {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(10) {
        let id = client.send_request(request.clone()).unwrap();
        let sent = Instant::now();
        while sent.elapsed() < Duration::from_millis(500) {
            if let Ok(Some((rid, response))) = client.receive_response()
                && rid == id
            {
                return response;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    panic!("no answer in 10 s");
}

#[test]
fn parameters_are_served_by_the_standard_services() {
    use ros2_client::rcl_interfaces::*;
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("parameters_are_served_by_the_standard_services");
        return;
    }
    let mut node = ros::node("parameter_test").unwrap();
    let service = |service: &str, ty: &str| {
        (Name::new("/lwr_driver", service).unwrap(), ServiceTypeName::new("rcl_interfaces", ty))
    };
    let (list_name, list_type) = service("list_parameters", "ListParameters");
    let (get_name, get_type) = service("get_parameters", "GetParameters");
    let (set_name, set_type) = service("set_parameters", "SetParameters");
    // The nodes serve parameters in the Cyclone DDS request mapping (their default peers'; vendor/ros2-client).
    let mapping = ros::service_mapping("cyclone").unwrap();
    let qos = ros::reliable_qos;
    let list = node
        .create_client::<ListParametersRequest, ListParametersResponse>(mapping, &list_name, &list_type, qos(), qos())
        .unwrap();
    let get = node
        .create_client::<GetParametersRequest, GetParametersResponse>(mapping, &get_name, &get_type, qos(), qos())
        .unwrap();
    let set = node
        .create_client::<SetParametersRequest, SetParametersResponse>(mapping, &set_name, &set_type, qos(), qos())
        .unwrap();
    let _driver = Processes(vec![spawn(
        env!("CARGO_BIN_EXE_lwr_driver"),
        &[
            "--params-file",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../config/lwr_driver.yaml"),
            "-p",
            "watchdog_cycles:=7",
            "-p",
            "exit_after_silence:=8",
        ],
    )]);

    let names = call(&list, ListParametersRequest { prefixes: vec![], depth: 0 }).result.names;
    for expected in ["fri_bind", "watchdog_cycles", "hold_stiffness", "use_sim_time"] {
        assert!(names.iter().any(|n| n == expected), "{expected} not in {names:?}");
    }
    let values = call(
        &get,
        GetParametersRequest { names: vec!["watchdog_cycles".into(), "fri_bind".into(), "hold_stiffness".into()] },
    )
    .values;
    assert_eq!(values[0].int_value, 7, "the override is what the node runs with");
    assert_eq!(values[1].string_value, "127.0.0.1:49938");
    assert_eq!(values[2].double_array, vec![3000.0, 3000.0, 1000.0, 1500.0, 300.0, 150.0, 150.0]);
    let mut changed = values[0].clone();
    changed.int_value = 3;
    let results = call(
        &set,
        SetParametersRequest {
            parameter: vec![ros2_client::parameters::raw::Parameter { name: "watchdog_cycles".into(), value: changed }],
        },
    )
    .results;
    assert!(!results[0].successful && results[0].reason.contains("start-up"), "{results:?}");
}
