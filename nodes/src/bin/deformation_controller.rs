//! `deformation_controller`: the force-control paper's deformation control as a ROS 2 node. Ticks once per
//! /lwr/joint_states (1 kHz), with the newest /ft_sensor/wrench turned into the world by the arm's own
//! kinematics; takes force commands on /deformation_controller/force_command and as the action
//! /deformation_controller/press, and models from /contact_estimator/model (adopted per `model_update`); publishes /lwr/joint_torque_command, stamped
//! with the joint state it answers (the driver measures the command's age from it), and
//! /deformation_controller/state. With a stale force reading it sends nothing, and the driver holds.
//! Joint states silent for `dead_after` after they flowed (a dead driver or middleware): it exits with an
//! error naming the stream, and the launch script stops the graph.
//! Each stream is taken from one pinned writer (`deformation_controller::standalone`).

use clap::Parser;
use softcontact_nodes::deformation_controller::{Params, standalone};
use softcontact_nodes::runtime::params::{self, ParamArgs};
use softcontact_nodes::runtime::ros;

#[derive(Parser)]
#[command(
    version,
    about = "Deformation control of a soft contact, as a ROS 2 node (parameters: config/deformation_controller.yaml)"
)]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("deformation_controller");
    let (p, declared) = params::load::<Params>("deformation_controller", &Args::parse().params)?;
    standalone::run(p, declared, ros::shutdown_flag()?)
}
