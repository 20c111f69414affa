//! The secure graph's enclaves (SROS2: one identity and one set of permissions a process) and what each
//! may publish and subscribe: the union of what its nodes write, read, serve and call, from the same
//! declarations the nodes take their names from (`softcontact_msgs::topics`), and nothing else.
//!
//! Least privilege: only the arm's own process writes the joint torques (and, in the separate layout,
//! only the controller's); only the estimator writes models; `/user` — `softcontact force`, `record`,
//! `replay`, the demo's client, a person's tools — sends force goals, calls the re-tare, reads every
//! stream, and reads (never sets) parameters.

use softcontact_msgs::topics;
use softcontact_security::Grant;

/// The enclave of each process and what runs in it.
pub const ENCLAVES: [(&str, &str); 7] = [
    ("/lwr_control", "the 1 kHz process: lwr_driver, ft_sensor and deformation_controller"),
    ("/contact_estimator", "contact_estimator"),
    ("/sim_arm", "the simulated arm and F/T box"),
    ("/lwr_driver", "lwr_driver alone (the separate layout)"),
    ("/ft_sensor", "ft_sensor alone (the separate layout)"),
    ("/deformation_controller", "deformation_controller alone (the separate layout)"),
    ("/user", "force goals, the re-tare, recording, replay, reading streams and parameters"),
];

/// What the enclave `name` may publish and subscribe (`None`: not one of [`ENCLAVES`]).
pub fn grant(name: &str) -> Option<Grant> {
    let mut g = Grant::default();
    match name {
        "/lwr_control" => {
            lwr_driver(&mut g);
            ft_sensor(&mut g);
            deformation_controller(&mut g);
        }
        "/contact_estimator" => contact_estimator(&mut g),
        "/sim_arm" => sim_arm(&mut g),
        "/lwr_driver" => lwr_driver(&mut g),
        "/ft_sensor" => ft_sensor(&mut g),
        "/deformation_controller" => deformation_controller(&mut g),
        "/user" => user(&mut g),
        _ => return None,
    }
    Some(g)
}

fn writes(g: &mut Grant, names: &[&str]) {
    for name in names {
        g.writes(name);
    }
}

fn reads(g: &mut Grant, names: &[&str]) {
    for name in names {
        g.reads(name);
    }
}

/// What every node of the suite does: the graph topic, its log, parameter events, its own parameter
/// services, and the simulated clock under `use_sim_time`.
fn node(g: &mut Grant, name: &str) {
    g.node_basics(name);
    g.reads(topics::CLOCK.name);
}

fn lwr_driver(g: &mut Grant) {
    node(g, "lwr_driver");
    writes(
        g,
        &[
            topics::JOINT_STATES.name,
            topics::ROBOT_JOINT_STATES.name,
            topics::EXTERNAL_TORQUE.name,
            topics::EE_POSE.name,
            topics::EE_TWIST.name,
            topics::TF.name,
            topics::TF_STATIC.name,
            topics::ROBOT_DESCRIPTION.name,
            topics::DIAGNOSTICS.name,
        ],
    );
    reads(g, &[topics::JOINT_TORQUE_COMMAND.name]);
}

fn ft_sensor(g: &mut Grant) {
    node(g, "ft_sensor");
    writes(g, &[topics::WRENCH_RAW.name, topics::WRENCH.name, topics::TARE.name, topics::DIAGNOSTICS.name]);
    reads(g, &[topics::EE_POSE.name]);
    g.server(topics::FT_BIAS_SERVICE);
}

fn deformation_controller(g: &mut Grant) {
    node(g, "deformation_controller");
    writes(g, &[topics::JOINT_TORQUE_COMMAND.name, topics::CONTROLLER_STATE.name]);
    reads(
        g,
        &[
            topics::FORCE_COMMAND.name,
            topics::CONTACT_MODEL.name,
            topics::JOINT_STATES.name,
            topics::EXTERNAL_TORQUE.name,
            topics::WRENCH.name,
        ],
    );
    g.server(topics::RETARE_SERVICE).client(topics::FT_BIAS_SERVICE).action_server(topics::PRESS_ACTION);
}

fn contact_estimator(g: &mut Grant) {
    node(g, "contact_estimator");
    writes(g, &[topics::CONTACT_STATE.name, topics::CONTACT_MODEL.name]);
    reads(g, &[topics::WRENCH.name, topics::EE_POSE.name, topics::EE_TWIST.name]);
}

fn sim_arm(g: &mut Grant) {
    node(g, "sim_arm");
    writes(g, &[topics::CLOCK.name, topics::CONTACT_WRENCH.name]);
}

/// Parameter services a user may call: those that read.
const PARAMETER_READS: [&str; 4] = ["get_parameters", "list_parameters", "describe_parameters", "get_parameter_types"];

fn user(g: &mut Grant) {
    g.subscribe("ros_discovery_info").publish("ros_discovery_info");
    g.publish("rt/rosout").publish("rt/parameter_events").subscribe("rt/parameter_events");
    // Every stream and every answer, read.
    g.subscribe("rt/*").subscribe("rr/*");
    writes(g, &[topics::FORCE_COMMAND.name]);
    g.action_client(topics::PRESS_ACTION).client(topics::RETARE_SERVICE);
    for service in PARAMETER_READS {
        g.client(&format!("/*/{service}"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_security::policy::{service, topic};

    fn who_may_publish(dds_name: &str) -> Vec<&'static str> {
        ENCLAVES.iter().map(|(n, _)| *n).filter(|n| grant(n).unwrap().may_publish(dds_name)).collect()
    }

    #[test]
    fn only_the_arms_own_process_and_the_controller_write_what_steers_the_arm() {
        assert_eq!(
            who_may_publish(&topic(topics::JOINT_TORQUE_COMMAND.name)),
            ["/lwr_control", "/deformation_controller"]
        );
        assert_eq!(who_may_publish(&topic(topics::CONTACT_MODEL.name)), ["/contact_estimator"]);
        assert_eq!(who_may_publish(&topic(topics::FORCE_COMMAND.name)), ["/user"], "force goals come from a user");
        // The measurements the controller acts on come from their own nodes only.
        for (t, owners) in [
            (topics::JOINT_STATES.name, ["/lwr_control", "/lwr_driver"]),
            (topics::WRENCH.name, ["/lwr_control", "/ft_sensor"]),
            (topics::EE_POSE.name, ["/lwr_control", "/lwr_driver"]),
        ] {
            assert_eq!(who_may_publish(&topic(t)), owners, "{t}");
        }
        // Replies of the services that move the arm come from their servers only.
        let (_, retare_reply) = service(topics::RETARE_SERVICE);
        assert_eq!(who_may_publish(&retare_reply), ["/lwr_control", "/deformation_controller"]);
        let goal = service(&format!("{}/_action/send_goal", topics::PRESS_ACTION));
        assert_eq!(who_may_publish(&goal.0), ["/user"]);
        assert_eq!(who_may_publish(&goal.1), ["/lwr_control", "/deformation_controller"]);
    }

    #[test]
    fn the_user_reads_parameters_and_streams_and_sets_nothing() {
        let user = grant("/user").unwrap();
        for node in ["lwr_driver", "ft_sensor", "deformation_controller", "contact_estimator", "sim_arm"] {
            assert!(user.may_publish(&format!("rq/{node}/get_parametersRequest")), "{node}");
            assert!(user.may_subscribe(&format!("rr/{node}/get_parametersReply")), "{node}");
            for set in ["set_parameters", "set_parameters_atomically"] {
                assert!(!user.may_publish(&format!("rq/{node}/{set}Request")), "{node} {set}");
                assert!(who_may_publish(&format!("rq/{node}/{set}Request")).is_empty(), "{node} {set}");
            }
        }
        assert!(user.may_subscribe("rt/ft_sensor/wrench") && user.may_subscribe("rt/lwr/joint_states"));
        assert!(!user.may_publish(&service(topics::FT_BIAS_SERVICE).0), "the bare tare is the controller's");
        assert!(user.may_publish(&service(topics::RETARE_SERVICE).0));
        assert!(!user.may_publish("rt/tf") && !user.may_publish("rt/clock"));
    }

    #[test]
    fn every_enclave_has_a_grant_and_an_unknown_one_has_none() {
        for (name, _) in ENCLAVES {
            softcontact_security::check_enclave_name(name).unwrap();
            assert!(!grant(name).unwrap().publish.is_empty(), "{name}");
        }
        assert!(grant("/stranger").is_none());
    }
}
