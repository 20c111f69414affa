//! `lwr_control`: the 1 kHz path in one process, the ROS 2 way (composition). lwr_driver,
//! ft_sensor and deformation_controller run as components: the FRI thread reads each measurement,
//! the controller computes the torque for that very measurement from the F/T node's newest force
//! (handed over in memory) and the driver answers with it — read → update → write, no DDS and no
//! allocation in between. Every topic of the three nodes is still published for monitoring and
//! recording, and each serves its parameters under its own name; /lwr/joint_torque_command is
//! published, not listened to (nobody outside the process commands the arm). The F/T node runs on a
//! thread of its own. The contact estimator (the slow path) stays a process of its own.
//!
//! Parameters: each component reads its own section of the files given (config/lwr_driver.yaml,
//! config/ft_sensor.yaml, config/deformation_controller.yaml); `-p name:=value` sets a parameter of every
//! component (one all three have, such as use_sim_time), `-p node:name:=value` one node's.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use anyhow::Context;
use clap::Parser;
use softcontact_nodes::deformation_controller::{self, InProcessController};
use softcontact_nodes::runtime::handover::Latest;
use softcontact_nodes::runtime::params::{self, ParamArgs};
use softcontact_nodes::runtime::ros;
use softcontact_nodes::{ft_sensor, lwr_driver};

#[derive(Parser)]
#[command(version, about = "lwr_driver, ft_sensor and deformation_controller composed in one process (the 1 kHz path)")]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("lwr_control");
    let args = Args::parse().params;
    args.check_node_prefixes(&["lwr_driver", "ft_sensor", "deformation_controller"])?;
    // A parameter of one node given to all three is refused by the other two: say how to aim it.
    const AIM: &str = "lwr_control hosts lwr_driver, ft_sensor and deformation_controller: a parameter of one of them is given as -p NODE:name:=value (docs/running.md)";
    let (driver_params, driver_declared) =
        params::load::<lwr_driver::Params>("lwr_driver", &args.for_node("lwr_driver")).context(AIM)?;
    let (ft_params, ft_declared) =
        params::load::<ft_sensor::Params>("ft_sensor", &args.for_node("ft_sensor")).context(AIM)?;
    let (controller_params, controller_declared) = params::load::<deformation_controller::Params>(
        "deformation_controller",
        &args.for_node("deformation_controller"),
    )
    .context(AIM)?;
    let stop = ros::shutdown_flag()?;

    let forces = Latest::shared();
    let poses = Latest::shared();
    let ft_links = ft_sensor::component::Links { poses: Some(poses.clone()), forces: Some(forces.clone()) };
    let ft_stop = stop.clone();
    let ft = std::thread::Builder::new().name("ft_sensor".into()).spawn(move || {
        let outcome = ft_sensor::component::run(ft_params, ft_declared, ft_links, ft_stop.clone());
        // The F/T node ended (an error, or its exit_after_silence): the process ends with it.
        ft_stop.store(true, Ordering::Relaxed);
        outcome
    })?;
    let controller = InProcessController::new(&controller_params, controller_declared, forces)?;
    let composed = |_: &mut _| Ok(controller);
    let driven = lwr_driver::component::run(driver_params, driver_declared, composed, Some(poses), Arc::clone(&stop));
    stop.store(true, Ordering::Relaxed);
    let sensed = ft.join().map_err(|_| anyhow::anyhow!("the ft_sensor thread panicked"))?;
    driven.context("lwr_driver")?;
    sensed.context("ft_sensor")
}
