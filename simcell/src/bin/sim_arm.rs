//! `sim_arm`: the simulated LWR IV, KRC, soft surface and Net F/T box behind the robot's and the
//! sensor's own UDP protocols, paced in real time (or in lockstep with the driver, publishing /clock).
//! Point the driver nodes at it as at the hardware. It publishes what only a simulator knows: the true
//! contact wrench on the hand (/sim_arm/contact_wrench, world, 1 kHz), and /clock in lockstep.

use softcontact_msgs::topics;
use std::sync::atomic::Ordering;
use std::time::Duration;

use clap::Parser;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::rosgraph_msgs::Clock;
use softcontact_nodes::messages;
use softcontact_nodes::runtime::params::{self, ParamArgs};
use softcontact_nodes::runtime::ros;
use softcontact_sim::{SimConfig, Simulator};
use softcontact_simcell::sim_arm::{Pacing, Params, SimArmConfig, SimArmServer, SurfaceKind};

#[derive(Parser)]
#[command(
    version,
    about = "Simulated KUKA LWR IV + soft surface + ATI Net F/T over FRI and RDT (UDP) (parameters: config/sim_arm.yaml)"
)]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("sim_arm");
    let (p, declared) = params::load::<Params>("sim_arm", &Args::parse().params)?;
    let stop = ros::shutdown_flag()?;
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), p.seed);
    config.krc.program = p.krl_program.program();
    (config.cycle, config.krc.cycle) = (p.fri_cycle, p.fri_cycle);
    let model = match p.surface {
        SurfaceKind::Sponge => Some(softcontact_sim::sponge()),
        SurfaceKind::Dice => Some(softcontact_sim::dice()),
        SurfaceKind::LabSponge => Some(softcontact_sim::lab_sponge()),
        SurfaceKind::LabDice => Some(softcontact_sim::lab_dice()),
        SurfaceKind::None => None,
    };
    match p.surface_model().map_err(|e| anyhow::anyhow!("surface_model: {e}"))?.or(model) {
        Some(m) => config.surface.as_mut().expect("preset has a surface").model = m,
        None => config.surface = None,
    }
    if matches!(p.surface, SurfaceKind::LabSponge | SurfaceKind::LabDice) {
        config.sensor = softcontact_sim::FtSensorConfig::gamma_drifting();
    }
    let box_settings = p.transducer.settings(p.rdt_rate, p.rdt_buffer as u32);
    config.sensor.calibration = box_settings.calibration()?;
    let sim = Simulator::new(config)?;
    let mut server = SimArmServer::bind(
        sim,
        SimArmConfig {
            fri_bind: p.fri_bind,
            fri_remote: p.fri_remote,
            rdt_bind: p.rdt_bind,
            http_bind: (p.http_bind.port() != 0).then_some(p.http_bind),
            box_settings,
            measurement_loss: p.drop_rate,
            command_loss: p.drop_rate,
            rdt_rate: p.rdt_rate,
            pacing: if p.lockstep {
                Pacing::Lockstep { timeout: Duration::from_millis(50) }
            } else {
                Pacing::RealTime { answer_wait: Duration::from_secs_f64(p.answer_wait) }
            },
            seed: p.seed,
        },
    )?;
    // The hardware it stands in for has no ROS side: a DDS participant only for what a simulator alone
    // knows — its time (/clock, in lockstep) and the true contact wrench, to grade runs on.
    let mut node = ros::node_with_parameters("sim_arm", declared)?;
    // /clock as `ros2 bag play --clock` publishes it (ClockQoS): the nodes read it the way ROS 2 nodes do.
    let clock = if p.lockstep { Some(ros::publisher(&mut node, &topics::CLOCK, ros::clock_qos())?) } else { None };
    let contact_wrench = ros::publisher(&mut node, &topics::CONTACT_WRENCH, ros::sensor_qos())?;
    let http = server.http_addr().map_or("no settings page".into(), |a| format!("netftapi2.xml at http://{a}"));
    eprintln!(
        "sim_arm: ready: FRI from {} to {}, RDT at {}, {http}",
        server.fri_addr()?,
        p.fri_remote,
        server.rdt_addr()?
    );
    eprintln!("sim_arm: FRI cycle {} ms", p.fri_cycle * 1e3);
    let cycles = (p.seconds > 0.0).then(|| (p.seconds * 1000.0).round());
    let stats = server.run(|sim| {
        // Stamped on the nodes' clock: the simulated time in lockstep, the system's in real time.
        let stamp = if clock.is_some() { Time::from_secs_f64(sim.time()) } else { Time::now() };
        if let Some(publisher) = &clock {
            let _ = publisher.publish(Clock { clock: stamp });
        }
        let _ = contact_wrench.publish(messages::contact_wrench(&sim.contact().force, stamp));
        !stop.load(Ordering::Relaxed) && cycles.is_none_or(|n| (sim.time() * 1000.0).round() < n)
    })?;
    eprintln!(
        "sim_arm: exit: {stats:?}; peak RSS {:.1} MB{}",
        ros::peak_rss_mb().unwrap_or(f64::NAN),
        ros::security_report()
    );
    Ok(())
}
