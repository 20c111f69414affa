//! `lwr_driver`: the LWR IV joint-torque interface as a ROS 2 node. Answers the KRC over FRI every
//! cycle (the reply goes out before anything is published), publishes /lwr/joint_states, /lwr/ee_pose,
//! /lwr/ee_twist, /tf and /tf_static, takes /lwr/joint_torque_command (effort = total torque, gravity
//! included), and reports its counters on /diagnostics once a second.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use clap::Parser;
use nalgebra::Isometry3;
use softcontact_dynamics::lwr4;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use softcontact_msgs::geometry_msgs::{
    Point, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Twist, TwistStamped, Vector3,
};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::std_msgs::Header;
use softcontact_msgs::tf2_msgs::TFMessage;
use softcontact_nodes::lwr_driver::{DriverConfig, DriverOutput, LwrDriver};
use softcontact_nodes::ros;
use softcontact_nodes::udp::FriClient;

#[derive(Parser)]
#[command(version, about = "KUKA LWR IV joint-torque interface over FRI, as a ROS 2 node")]
struct Args {
    /// Where the KRC sends its measurements (the KRC's FRIHOST:FRISOCK).
    #[arg(long, default_value = "127.0.0.1:49938")]
    fri_bind: SocketAddr,
    /// A command older than this many cycles makes the driver hold position.
    #[arg(long, default_value_t = 5)]
    watchdog_cycles: u64,
    /// Do not ask the KRL program to start command mode (monitor only).
    #[arg(long)]
    monitor_only: bool,
    /// Stop after this many seconds without a measurement (0: wait forever).
    #[arg(long, default_value_t = 0.0)]
    exit_after_silence: f64,
    /// Stamp messages with the simulated time of /clock.
    #[arg(long)]
    use_sim_time: bool,
}

fn header(frame: &str, stamp: Time) -> Header {
    Header { stamp, frame_id: frame.into() }
}

fn pose_parts(p: &Isometry3<f64>) -> (Vector3, Quaternion) {
    let t = p.translation.vector;
    let q = p.rotation;
    (Vector3 { x: t.x, y: t.y, z: t.z }, Quaternion { x: q.i, y: q.j, z: q.k, w: q.w })
}

fn transform(parent: &str, child: &str, p: &Isometry3<f64>, stamp: Time) -> TransformStamped {
    let (translation, rotation) = pose_parts(p);
    TransformStamped {
        header: header(parent, stamp),
        child_frame_id: child.into(),
        transform: Transform { translation, rotation },
    }
}

fn diagnostics(driver: &LwrDriver, last: Option<&DriverOutput>, stamp: Time) -> DiagnosticArray {
    let c = driver.counters;
    let (level, message) = match last {
        None => (DiagnosticStatus::STALE, "no FRI measurement yet".to_string()),
        Some(o) if o.holding => {
            (DiagnosticStatus::WARN, format!("holding position ({:?}, quality {:?})", o.state, o.quality))
        }
        Some(o) => (DiagnosticStatus::OK, format!("{:?}, quality {:?}", o.state, o.quality)),
    };
    ros::diagnostics(
        stamp,
        "lwr_driver: FRI",
        "kuka_lwr4",
        level,
        message,
        &[
            ("measurements", c.measurements),
            ("lost", c.lost),
            ("out_of_order", c.out_of_order),
            ("malformed", c.malformed),
            ("stale_cycles", c.stale_cycles),
            ("clipped_cycles", c.clipped_cycles),
            ("overspeed_cycles", c.overspeed_cycles),
            ("commands_refused", c.commands_refused),
        ],
    )
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let config = DriverConfig {
        watchdog_cycles: args.watchdog_cycles,
        request_command_mode: !args.monitor_only,
        ..Default::default()
    };
    let mut client = FriClient::bind(args.fri_bind, LwrDriver::new(config))?;
    let mut node = ros::node("lwr_driver")?;
    let joint_states = ros::publisher::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos())?;
    let ee_pose = ros::publisher::<PoseStamped>(&mut node, "/lwr/ee_pose", ros::sensor_qos())?;
    let ee_twist = ros::publisher::<TwistStamped>(&mut node, "/lwr/ee_twist", ros::sensor_qos())?;
    let tf = ros::publisher::<TFMessage>(&mut node, "/tf", ros::sensor_qos())?;
    let tf_static = ros::publisher::<TFMessage>(&mut node, "/tf_static", ros::latched_qos())?;
    let diag = ros::publisher::<DiagnosticArray>(&mut node, "/diagnostics", ros::reliable_qos())?;
    let commands = ros::subscription::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos())?;
    let mut clock = ros::Clock::new(&mut node, args.use_sim_time)?;

    // The fixed frames below the tool, from the URDF: the sensor as seen from the tool.
    let model = lwr4::model();
    let mut data = model.data();
    model.forward_kinematics(&mut data, &[0.0; 7]);
    let tool_pose0 = model.frame_pose(&data, model.frame_id(lwr4::TOOL_FRAME)?);
    let sensor_pose0 = model.frame_pose(&data, model.frame_id(lwr4::FT_SENSOR_FRAME)?);
    tf_static.publish(TFMessage {
        transforms: vec![transform(
            lwr4::TOOL_FRAME,
            lwr4::FT_SENSOR_FRAME,
            &(tool_pose0.inverse() * sensor_pose0),
            clock.now(),
        )],
    })?;
    let names: Vec<String> = model.joints.iter().map(|j| j.name.clone()).collect();
    eprintln!("lwr_driver: FRI on {}, domain {}", client.local_addr()?, node.domain_id());

    let mut last: Option<DriverOutput> = None;
    let mut next_diagnostics = Instant::now();
    let mut last_seen = Instant::now();
    loop {
        let output = client.cycle(Duration::from_millis(5))?;
        // Newest torque command wins; a bad one is refused and counted, the previous one stays.
        while let Ok(Some((cmd, _))) = commands.take() {
            if let Err(e) = client.driver.set_command(&cmd.effort) {
                eprintln!("lwr_driver: torque command refused: {e}");
            }
        }
        if let Some(out) = output {
            last_seen = Instant::now();
            let stamp = clock.now();
            let h = header("world", stamp);
            joint_states.publish(JointState {
                header: h.clone(),
                name: names.clone(),
                position: out.q.to_vec(),
                velocity: out.dq.to_vec(),
                effort: out.effort.to_vec(),
            })?;
            let (t, q) = pose_parts(&out.tool_pose);
            ee_pose.publish(PoseStamped {
                header: h.clone(),
                pose: Pose { position: Point { x: t.x, y: t.y, z: t.z }, orientation: q },
            })?;
            let v = out.tool_twist;
            ee_twist.publish(TwistStamped {
                header: h,
                twist: Twist {
                    linear: Vector3 { x: v[0], y: v[1], z: v[2] },
                    angular: Vector3 { x: v[3], y: v[4], z: v[5] },
                },
            })?;
            tf.publish(TFMessage { transforms: vec![transform("world", lwr4::TOOL_FRAME, &out.tool_pose, stamp)] })?;
            last = Some(out);
        } else if args.exit_after_silence > 0.0 && last_seen.elapsed().as_secs_f64() > args.exit_after_silence {
            diag.publish(diagnostics(&client.driver, last.as_ref(), clock.now()))?;
            eprintln!(
                "lwr_driver: no measurement for {} s, exiting; {:?}",
                args.exit_after_silence, client.driver.counters
            );
            return Ok(());
        }
        if Instant::now() >= next_diagnostics {
            diag.publish(diagnostics(&client.driver, last.as_ref(), clock.now()))?;
            next_diagnostics += Duration::from_secs(1);
        }
    }
}
