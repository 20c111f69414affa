//! `contact_estimator`: learns the contact model of the surface under the hand online. Pairs each
//! /ft_sensor/wrench with the newest /lwr/ee_pose and /lwr/ee_twist, detects the onset, keeps the
//! sliding window, publishes /contact_estimator/state at `state_rate` and, every `refit_period`, every
//! candidate's cross-validated fit with the chosen model and the surface position on
//! /contact_estimator/model. /ft_sensor/wrench or /lwr/ee_pose silent for `dead_after` after they flowed
//! (a dead publisher or middleware): it exits with an error naming the stream, and the launch script
//! stops the graph.

use clap::Parser;
use softcontact_nodes::contact_estimator::{Params, component};
use softcontact_nodes::runtime::params::{self, ParamArgs};
use softcontact_nodes::runtime::ros;

#[derive(Parser)]
#[command(
    version,
    about = "Online contact-model estimation, as a ROS 2 node (parameters: config/contact_estimator.yaml)"
)]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("contact_estimator");
    let (p, declared) = params::load::<Params>("contact_estimator", &Args::parse().params)?;
    component::run(p, declared, ros::shutdown_flag()?)
}
