//! `sim_arm`: the simulated LWR IV, KRC, soft surface and Net F/T box behind the robot's and the
//! sensor's own UDP protocols, paced in real time. Point the driver nodes at it as at the hardware.

use std::net::SocketAddr;

use clap::{Parser, ValueEnum};
use std::time::Duration;

use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::rosgraph_msgs::Clock;
use softcontact_nodes::ros;
use softcontact_nodes::sim_arm::{Pacing, SimArmConfig, SimArmServer};
use softcontact_sim::{SimConfig, Simulator};

#[derive(Clone, Copy, ValueEnum)]
enum SurfaceKind {
    Sponge,
    Dice,
    None,
}

#[derive(Parser)]
#[command(version, about = "Simulated KUKA LWR IV + soft surface + ATI Net F/T over FRI and RDT (UDP)")]
struct Args {
    /// Where the FRI driver listens (the KRC's FRIHOST:FRISOCK).
    #[arg(long, default_value = "127.0.0.1:49938")]
    fri_remote: SocketAddr,
    /// The KRC side's own FRI address.
    #[arg(long, default_value = "127.0.0.1:0")]
    fri_bind: SocketAddr,
    /// The Net F/T box's RDT address.
    #[arg(long, default_value = "127.0.0.1:49152")]
    rdt_bind: SocketAddr,
    #[arg(long, value_enum, default_value = "sponge")]
    surface: SurfaceKind,
    /// Stop after this many simulated seconds (default: run until killed).
    #[arg(long)]
    seconds: Option<f64>,
    /// Fraction of FRI datagrams lost once commanding, in each direction.
    #[arg(long, default_value_t = 0.0)]
    drop_rate: f64,
    /// RDT records per second while streaming (the box's comrdtrate).
    #[arg(long, default_value_t = 1000.0)]
    rdt_rate: f64,
    /// Faster than real time: step as soon as the driver has answered, and publish the simulated time
    /// on /clock (run the nodes with --use-sim-time).
    #[arg(long)]
    lockstep: bool,
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    if !(0.0..1.0).contains(&args.drop_rate) {
        anyhow::bail!("--drop-rate must lie in [0, 1)");
    }
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), args.seed);
    match args.surface {
        SurfaceKind::Sponge => {}
        SurfaceKind::Dice => config.surface.as_mut().expect("preset has a surface").model = softcontact_sim::dice(),
        SurfaceKind::None => config.surface = None,
    }
    let sim = Simulator::new(config)?;
    let mut server = SimArmServer::bind(
        sim,
        SimArmConfig {
            fri_bind: args.fri_bind,
            fri_remote: args.fri_remote,
            rdt_bind: args.rdt_bind,
            measurement_loss: args.drop_rate,
            command_loss: args.drop_rate,
            rdt_rate: args.rdt_rate,
            pacing: if args.lockstep {
                Pacing::Lockstep { timeout: Duration::from_millis(50) }
            } else {
                Pacing::RealTime
            },
            seed: args.seed,
        },
    )?;
    let clock = if args.lockstep {
        let mut node = ros::node("sim_arm")?;
        Some((ros::publisher::<Clock>(&mut node, "/clock", ros::reliable_qos())?, node))
    } else {
        None
    };
    eprintln!("sim_arm: FRI from {} to {}, RDT at {}", server.fri_addr()?, args.fri_remote, server.rdt_addr()?);
    let cycles = args.seconds.map(|s| (s * 1000.0).round() as u64);
    let stats = server.run(|sim| {
        if let Some((publisher, _)) = &clock {
            let _ = publisher.publish(Clock { clock: Time::from_secs_f64(sim.time()) });
        }
        cycles.is_none_or(|n| (sim.time() * 1000.0).round() < n as f64)
    })?;
    eprintln!("sim_arm: {stats:?}");
    Ok(())
}
