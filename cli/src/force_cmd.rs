//! `softcontact force`: send one force command to the running deformation controller over DDS and
//! report the force reached at the end of the move (seed 001 reads the force there).

use std::time::{Duration, Instant};

use softcontact_msgs::softcontact_msgs::{ControllerState, ForceCommand};
use softcontact_nodes::ros;

#[derive(Debug, clap::Args)]
pub struct ForceArgs {
    /// The normal force to reach [N].
    pub force: f64,
    /// Duration of the quintic move [s].
    #[arg(long, default_value_t = 2.0)]
    pub duration: f64,
    /// Exit with an error if the force at the end of the move is off by more than this fraction.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Send the command and return once the controller has taken it.
    #[arg(long)]
    pub no_wait: bool,
}

pub fn run(args: &ForceArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.force.is_finite() && args.force >= 0.0, "the force must be a number ≥ 0");
    anyhow::ensure!(args.duration.is_finite() && args.duration > 0.0, "the duration must be positive");
    let mut node = ros::node("softcontact_force")?;
    let states = ros::subscription::<ControllerState>(&mut node, "/deformation_controller/state", ros::sensor_qos())?;
    let commands =
        ros::publisher::<ForceCommand>(&mut node, "/deformation_controller/force_command", ros::reliable_qos())?;
    let next_state = |timeout: Duration| -> Option<ControllerState> {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            if let Ok(Some((s, _))) = states.take() {
                return Some(s);
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        None
    };
    let first = next_state(Duration::from_secs(10)).ok_or_else(|| {
        anyhow::anyhow!(
            "no /deformation_controller/state in 10 s: is the controller running (ROS_DOMAIN_ID {})?",
            node.domain_id()
        )
    })?;
    anyhow::ensure!(first.in_contact, "the controller has no contact yet: force commands wait for the onset");
    // Discovery runs both ways: give the controller's reader time to match this writer, and resend if
    // the command was not taken (a reliable writer drops samples for readers it has not matched yet).
    std::thread::sleep(Duration::from_millis(300));
    let command = ForceCommand { force: args.force, duration: args.duration };
    let mut accepted = None;
    'send: for _ in 0..3 {
        commands.publish(command.clone())?;
        let end = Instant::now() + Duration::from_secs(1);
        while Instant::now() < end {
            match next_state(Duration::from_millis(100)) {
                Some(s) if (s.f_cmd - args.force).abs() < 1e-9 => {
                    accepted = Some(Instant::now());
                    break 'send;
                }
                _ => {}
            }
        }
    }
    let accepted = accepted.ok_or_else(|| {
        anyhow::anyhow!("the controller did not take {} N (out of its limits? see its log or /rosout)", args.force)
    })?;
    println!("force command {:.2} N over {:.2} s taken", args.force, args.duration);
    if args.no_wait {
        return Ok(());
    }
    // The force over the last 50 ms of the move.
    let end = accepted + Duration::from_secs_f64(args.duration);
    let mut at_end = Vec::new();
    while Instant::now() < end + Duration::from_millis(20) {
        if let Some(s) = next_state(Duration::from_millis(100))
            && Instant::now() + Duration::from_millis(50) >= end
        {
            anyhow::ensure!(!s.contact_lost, "contact lost during the move");
            at_end.push(s.f);
        }
    }
    anyhow::ensure!(!at_end.is_empty(), "no controller state at the end of the move");
    let reached = at_end.iter().sum::<f64>() / at_end.len() as f64;
    let error = (reached - args.force) / args.force.max(1e-9);
    println!("reached {reached:.2} N for {:.2} N ({:+.2} %)", args.force, error * 100.0);
    if let Some(tolerance) = args.tolerance {
        anyhow::ensure!(error.abs() <= tolerance, "off by {:.2} %, beyond ±{:.2} %", error * 100.0, tolerance * 100.0);
    }
    Ok(())
}
