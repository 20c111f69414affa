//! `ft_sensor`: the ATI Net F/T as a ROS 2 node. Streams RDT records, publishes /ft_sensor/wrench_raw
//! (bias removed) and /ft_sensor/wrench (also the hand's weight removed, for the orientation taken from
//! /lwr/ee_pose), serves /ft_sensor/bias (std_srvs/Trigger: software tare), and reports stale,
//! saturated or faulty data on /diagnostics.

use std::time::{Duration, Instant};

use clap::Parser;
use nalgebra::{UnitQuaternion, Vector3};
use ros2_client::{Name, ServiceTypeName};
use softcontact_dynamics::lwr4;
use softcontact_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use softcontact_msgs::geometry_msgs::{PoseStamped, WrenchStamped};
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use softcontact_nodes::contact_estimator::ForcePairing;
use softcontact_nodes::ft_sensor::{FtConfig, FtSensorNode, Params};
use softcontact_nodes::geometry;
use softcontact_nodes::messages;
use softcontact_nodes::params::{self, ParamArgs};
use softcontact_nodes::ros::{self, LogLevel};
use softcontact_nodes::udp::RdtClient;

#[derive(Parser)]
#[command(version, about = "ATI Net F/T over RDT, as a ROS 2 node (parameters: config/ft_sensor.yaml)")]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("ft_sensor");
    let (p, declared) = params::load::<Params>("ft_sensor", &Args::parse().params)?;
    let config = FtConfig {
        calibration: p.calibration().map_err(anyhow::Error::msg)?,
        tool: lwr4::tool_load(),
        gravity: Vector3::new(0.0, 0.0, -9.81),
        low_pass: (p.low_pass > 0.0).then_some(p.low_pass),
        sample_rate: p.rate,
    };
    let stop = ros::shutdown_flag()?;
    let mut client = RdtClient::connect(p.sensor, FtSensorNode::new(config).map_err(anyhow::Error::msg)?)?;
    let mut node = ros::node_with_parameters("ft_sensor", declared)?;
    let raw_pub = ros::publisher::<WrenchStamped>(&mut node, "/ft_sensor/wrench_raw", ros::sensor_qos())?;
    let wrench_pub = ros::publisher::<WrenchStamped>(&mut node, "/ft_sensor/wrench", ros::sensor_qos())?;
    let diag = ros::publisher::<DiagnosticArray>(&mut node, "/diagnostics", ros::reliable_qos())?;
    let poses = ros::subscription::<PoseStamped>(&mut node, "/lwr/ee_pose", ros::sensor_qos())?;
    let mut clock = ros::Clock::new(&mut node, p.use_sim_time)?;
    let bias = node.create_server::<TriggerRequest, TriggerResponse>(
        ros::service_mapping(&p.service_mapping)?,
        &Name::new("/ft_sensor", "bias")?,
        &ServiceTypeName::new("std_srvs", "Trigger"),
        ros::reliable_qos(),
        ros::reliable_qos(),
    )?;

    let tool_to_sensor = ForcePairing::urdf_tool_to_sensor()?;

    client.start()?;
    ros::log(&node, LogLevel::Info, &format!("ready: streaming from {}, domain {}", p.sensor, node.domain_id()));
    let mut orientation: Option<UnitQuaternion<f64>> = None;
    let mut last_record = Instant::now();
    let mut last_status = 0u32;
    let mut started = Instant::now();
    let mut next_diagnostics = Instant::now();
    // Tared yet? With `tare_after` < 0 the user tares through the service; until then only raw data.
    let mut tared = p.tare_after < 0.0;
    let mut tare_due: Option<Instant> = None;
    while !ros::stopping(&stop) {
        while let Ok(Some((pose, _))) = poses.take() {
            orientation = Some(geometry::pose_of(&pose.pose).1 * tool_to_sensor);
        }
        if let Some(out) = client.receive(Duration::from_millis(2), orientation.as_ref())? {
            last_record = Instant::now();
            last_status = out.status.0;
            if !out.invalid {
                let stamp = clock.now();
                raw_pub.publish(messages::wrench(&out.raw, stamp))?;
                if let Some(c) = out.compensated.filter(|_| tared) {
                    wrench_pub.publish(messages::wrench(&c, stamp))?;
                }
            }
        }
        if !tared && orientation.is_some() {
            let due = *tare_due.get_or_insert_with(|| Instant::now() + Duration::from_secs_f64(p.tare_after));
            if Instant::now() >= due {
                match client.node.tare(orientation.as_ref()) {
                    Ok(b) => {
                        tared = true;
                        ros::log(&node, LogLevel::Info, &format!("tared at start-up: bias {b:.3?}"));
                    }
                    Err(e) => ros::log(&node, LogLevel::Warn, &format!("tare failed: {e}")),
                }
            }
        }
        while let Ok(Some((id, _))) = bias.receive_request() {
            let response = match client.node.tare(orientation.as_ref()) {
                Ok(b) => {
                    tared = true;
                    TriggerResponse { success: true, message: format!("bias set to {b:?}") }
                }
                Err(e) => TriggerResponse { success: false, message: e },
            };
            bias.send_response(id, response)?;
        }
        let silent = last_record.elapsed().as_secs_f64();
        if silent > 1.0 && started.elapsed().as_secs_f64() > 1.0 {
            // The box may have lost our stream (a newer start from elsewhere, a reboot): ask again.
            client.start()?;
            started = Instant::now();
        }
        if p.exit_after_silence > 0.0 && silent > p.exit_after_silence {
            ros::log(&node, LogLevel::Info, &format!("no record for {} s, exiting", p.exit_after_silence));
            break;
        }
        if Instant::now() >= next_diagnostics {
            let c = client.node.counters;
            let status = softcontact_wire::rdt::Status(last_status);
            let (level, message) = if silent > p.stale_after {
                (DiagnosticStatus::STALE, format!("no record for {silent:.3} s"))
            } else if status.is_saturated() || status.is_error() {
                (DiagnosticStatus::ERROR, status.describe().join(", "))
            } else if orientation.is_none() {
                (DiagnosticStatus::WARN, "no /lwr/ee_pose yet: tool gravity not compensated".into())
            } else if !tared {
                (DiagnosticStatus::WARN, "not tared yet: /ft_sensor/wrench waits".into())
            } else {
                (DiagnosticStatus::OK, "streaming".into())
            };
            diag.publish(ros::diagnostics(
                clock.now(),
                "ft_sensor: RDT",
                &p.sensor.to_string(),
                level,
                message,
                &[
                    ("records", c.records),
                    ("lost", c.lost),
                    ("out_of_order", c.out_of_order),
                    ("malformed", c.malformed),
                    ("saturated", c.saturated),
                    ("errors", c.errors),
                ],
            ))?;
            next_diagnostics += Duration::from_secs(1);
        }
    }
    client.stop()?;
    eprintln!("ft_sensor: exit: {:?}; peak RSS {:.1} MB", client.node.counters, ros::peak_rss_mb().unwrap_or(f64::NAN));
    Ok(())
}
