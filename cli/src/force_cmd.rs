//! `softcontact force`: send one force command to the running deformation controller as a goal of its
//! action /deformation_controller/press, and report the result: the force reached at the end of the
//! move (the force-control paper reads the force there) and its error.

use softcontact_msgs::topics;
use std::time::{Duration, Instant};

use ros2_client::ActionTypeName;
use ros2_client::action::{ActionClient, ActionClientQosPolicies, GoalId, GoalStatusEnum};
use softcontact_msgs::softcontact_msgs::{PressForceFeedback, PressForceGoal, PressForceResult};
use softcontact_nodes::deformation_controller::PRESS_ACTION;
use softcontact_nodes::runtime::ros;

#[derive(Debug, clap::Args)]
pub struct ForceArgs {
    /// The normal force to reach (N) (a negative one is refused with a reason, not taken for an option).
    #[arg(allow_hyphen_values = true, value_parser = crate::ranges::real(-1e6, 1e6, " N"))]
    pub force: f64,
    /// Duration of the quintic move (s).
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true, value_parser = crate::ranges::real(-1e6, 1e6, " s"))]
    pub duration: f64,
    /// Exit with an error if the force at the end of the move is off by more than this fraction.
    #[arg(long, value_parser = crate::ranges::real(0.0, 1.0, ""))]
    pub tolerance: Option<f64>,
    /// Send the command and return once the controller has taken it.
    #[arg(long)]
    pub no_wait: bool,
    /// Print the action's feedback (phase, force, deformation) as the move goes.
    #[arg(long)]
    pub verbose: bool,
    /// Service mapping of the controller's middleware: cyclone, enhanced (Fast DDS) or basic.
    #[arg(long, default_value = "cyclone")]
    pub service_mapping: String,
    /// The namespace the graph runs in (its nodes started with `-r __ns:=/NS`).
    #[arg(long, default_value = "/")]
    pub namespace: String,
    /// The enclave on a secure graph (`ROS_SECURITY_ENABLE=true`): /user, whose permissions send force goals.
    #[arg(long)]
    pub enclave: Option<String>,
}

pub fn run(args: &ForceArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.force.is_finite() && args.force >= 0.0, "the force must be a number ≥ 0");
    anyhow::ensure!(args.duration.is_finite() && args.duration > 0.0, "the duration must be positive");
    let mut node = ros::tool_node("softcontact_force", &args.namespace, args.enclave.as_deref())?;
    let action = ros::resolve(&node, PRESS_ACTION)?.to_string();
    let states = ros::subscription(&mut node, &topics::CONTROLLER_STATE, ros::sensor_qos())?;
    let press = press_client(&mut node, &args.service_mapping)?;
    // The controller publishes its state while it commands the arm; without it (no contact yet, the KRC
    // not in torque mode, a fault) the goal is sent all the same, and the controller says why it refuses.
    let alive = (0..200).any(|_| {
        std::thread::sleep(Duration::from_millis(10));
        states.take().ok().flatten().is_some()
    });
    // Discovery runs both ways: give the action server's readers time to match these writers, and send
    // the goal again if it went unanswered (a request to a reader not matched yet is lost).
    std::thread::sleep(Duration::from_millis(300));
    let goal = PressForceGoal { force: args.force, duration: args.duration };
    let mut sent = None;
    'send: for _ in 0..3 {
        let (request, goal_id) =
            press.send_goal(goal.clone()).map_err(|e| anyhow::anyhow!("sending the goal: {e:?}"))?;
        let end = Instant::now() + Duration::from_secs(1);
        while Instant::now() < end {
            if let Ok(Some(response)) = press.receive_goal_response(request) {
                sent = Some((response.accepted, goal_id));
                break 'send;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    let (accepted, goal_id) = sent.ok_or_else(|| match alive {
        true => anyhow::anyhow!("no answer from {action} (--service-mapping of the controller?)"),
        false => anyhow::anyhow!(
            "no answer from {action} and no controller state: is the controller running (ROS_DOMAIN_ID {}, --namespace {})?",
            node.domain_id(),
            args.namespace
        ),
    })?;
    if !accepted {
        // The controller keeps the reason as the refused goal's result.
        let why = result(&press, goal_id, 2.0, false)?
            .map_or_else(|| "see its log or /rosout".to_string(), |(_, r)| r.message);
        anyhow::bail!("the controller refused {:?} N over {:?} s: {why}", args.force, args.duration);
    }
    println!("force command {:.2} N over {:.2} s taken", args.force, args.duration);
    if args.no_wait {
        return Ok(());
    }
    // The result comes at the end of the move.
    let outcome = result(&press, goal_id, args.duration + 3.0, args.verbose)?;
    let (status, result) = outcome.ok_or_else(|| anyhow::anyhow!("no result from {PRESS_ACTION}"))?;
    anyhow::ensure!(status == GoalStatusEnum::Succeeded, "the press ended {status:?}: {}", result.message);
    if args.force == 0.0 {
        println!("reached {:.2} N for 0 N", result.force);
        return Ok(());
    }
    let error = result.error / args.force;
    println!("reached {:.2} N for {:.2} N ({:+.2} %)", result.force, args.force, error * 100.0);
    if let Some(tolerance) = args.tolerance {
        anyhow::ensure!(error.abs() <= tolerance, "off by {:.2} %, beyond ±{:.2} %", error * 100.0, tolerance * 100.0);
    }
    Ok(())
}

type Press = ActionClient<PressForceGoal, PressForceResult, PressForceFeedback>;

/// The goal's result, waiting up to `seconds` (asked for once more if the first request went astray);
/// `verbose` prints the feedback meanwhile.
fn result(
    press: &Press,
    goal_id: GoalId,
    seconds: f64,
    verbose: bool,
) -> anyhow::Result<Option<(GoalStatusEnum, PressForceResult)>> {
    for _ in 0..2 {
        let request = press.request_result(goal_id).map_err(|e| anyhow::anyhow!("asking for the result: {e:?}"))?;
        let end = Instant::now() + Duration::from_secs_f64(seconds);
        while Instant::now() < end {
            while let Ok(Some(f)) = press.receive_feedback(goal_id) {
                if verbose {
                    println!("  {}: {:.2} N, deformation {:.2} mm", f.phase, f.force, f.deformation * 1e3);
                }
            }
            if let Ok(Some(r)) = press.receive_result(request) {
                return Ok(Some(r));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    Ok(None)
}

/// The client of the controller's force action, with the QoS of ROS 2 actions.
fn press_client(node: &mut ros2_client::Node, mapping: &str) -> anyhow::Result<Press> {
    let name = ros::resolve(node, PRESS_ACTION)?;
    let [goal_service, result_service, cancel_service, feedback_subscription, status_subscription] =
        ros::press_action_qos();
    let qos = ActionClientQosPolicies {
        goal_service,
        result_service,
        cancel_service,
        feedback_subscription,
        status_subscription,
    };
    Ok(node.create_action_client(
        ros::service_mapping(mapping)?,
        &name,
        &ActionTypeName::new("softcontact_msgs", "PressForce"),
        qos,
    )?)
}
