//! `lwr_driver`: the LWR IV joint-torque interface as a ROS 2 node. Answers the KRC over FRI every
//! cycle (the reply goes out before anything is published), publishes /lwr/joint_states, /lwr/ee_pose,
//! /lwr/ee_twist, /tf and /tf_static, takes /lwr/joint_torque_command (effort = total torque, gravity
//! included), and reports its counters on /diagnostics once a second. Torque commands that flowed and
//! stopped for `dead_after` while the KRC commands (a dead controller or middleware): the watchdog holds
//! the arm, and the driver logs an error once and reports ERROR on /diagnostics; it never exits for it.

use clap::Parser;
use softcontact_nodes::lwr_driver::commander::TopicCommands;
use softcontact_nodes::lwr_driver::{Params, component};
use softcontact_nodes::runtime::params::{self, ParamArgs};
use softcontact_nodes::runtime::ros;

#[derive(Parser)]
#[command(
    version,
    about = "KUKA LWR IV joint-torque interface over FRI, as a ROS 2 node (parameters: config/lwr_driver.yaml)"
)]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("lwr_driver");
    let (p, declared) = params::load::<Params>("lwr_driver", &Args::parse().params)?;
    component::run(p, declared, TopicCommands::new, None, ros::shutdown_flag()?)
}
