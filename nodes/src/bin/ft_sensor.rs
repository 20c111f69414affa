//! `ft_sensor`: the ATI Net F/T as a ROS 2 node. Streams RDT records, publishes /ft_sensor/wrench_raw
//! (bias removed) and /ft_sensor/wrench (also the hand's weight removed, for the orientation taken from
//! /lwr/ee_pose), serves /ft_sensor/bias (std_srvs/Trigger: software tare, refused in contact or in
//! motion, with the reason in the answer), and reports stale, saturated or faulty data and network
//! errors on /diagnostics. No datagram and no network error ends it: it asks the box to stream until it
//! does. /lwr/ee_pose silent for `dead_after` after it flowed: the hand's orientation is unknown, so
//! /ft_sensor/wrench is withheld (ERROR on /diagnostics) until poses flow again.

use clap::Parser;
use softcontact_nodes::ft_sensor::{Params, component};
use softcontact_nodes::runtime::params::{self, ParamArgs};
use softcontact_nodes::runtime::ros;

#[derive(Parser)]
#[command(version, about = "ATI Net F/T over RDT, as a ROS 2 node (parameters: config/ft_sensor.yaml)")]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("ft_sensor");
    let (p, declared) = params::load::<Params>("ft_sensor", &Args::parse().params)?;
    component::run(p, declared, component::Links::default(), ros::shutdown_flag()?)
}
