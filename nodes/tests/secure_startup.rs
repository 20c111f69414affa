//! A secure node's start-up, as every node of the suite starts: its spinner thread comes up (and creates
//! its graph readers) while the node's own thread goes on creating topics, publishers and subscriptions
//! on the same participant. Both take the participant's lock and DDS-Security's plugins lock; taken in
//! opposite orders, the two threads wait for each other for good and the node never joins the graph
//! (the 1 kHz loop of lwr_control never started, the FRI peer saw every cycle overrun). Each start here
//! has to finish within a deadline.
//!
//! Needs the `security` feature: `cargo test --release --features softcontact/security -p softcontact-nodes
//! --test secure_startup`.

#[allow(dead_code)] // the helpers of the process tests, unused here
mod common;

use std::sync::mpsc;
use std::time::Duration;

use common::{INNER, in_isolated_namespace_with};
use softcontact_msgs::std_msgs;
use softcontact_nodes::runtime::ros;
use softcontact_security::{Grant, keystore};

/// Starts of a node, each racing its spinner against its own thread.
const STARTS: usize = 20;
/// Topics the node's thread creates while its spinner comes up (a topic is cheap: many fit in the
/// spinner's first milliseconds), then publishers and subscriptions.
const TOPICS: usize = 300;
const ENDPOINTS: usize = 4;

fn start_nodes_racing_their_spinners() {
    let qos = ros::reliable_qos();
    let string_type = ros2_client::MessageTypeName::new("std_msgs", "String");
    for start in 0..STARTS {
        let name = format!("startup_{start}");
        let mut node = ros::tool_node(&name, "/", Some("/user")).expect("a secure node");
        ros::spin(&mut node, &name).expect("its spinner");
        for topic in 0..TOPICS {
            let path = ros2_client::Name::new(&format!("/startup/start_{start}"), &format!("topic_{topic}")).unwrap();
            node.create_topic(&path, string_type.clone(), &qos).unwrap();
        }
        for endpoint in 0..ENDPOINTS {
            let path = format!("/startup/start_{start}/endpoint_{endpoint}");
            let _p = ros::publisher_by_name::<std_msgs::String>(&mut node, &path, qos.clone()).unwrap();
            let _s = ros::subscription_by_name::<std_msgs::String>(&mut node, &path, qos.clone()).unwrap();
        }
    }
}

#[test]
fn a_secure_node_starts_while_its_spinner_comes_up() {
    if !cfg!(feature = "security") {
        eprintln!("built without the security feature: nothing to test");
        return;
    }
    if std::env::var(INNER).is_err() {
        let dir = tempfile::tempdir().unwrap();
        let store = dir.path().join("keystore");
        keystore::create_keystore(&store, 0).unwrap();
        keystore::create_enclave(&store, "/user", &Grant::everything(), 0).unwrap();
        in_isolated_namespace_with(
            "a_secure_node_starts_while_its_spinner_comes_up",
            &[
                ("ROS_SECURITY_ENABLE", "true".as_ref()),
                ("ROS_SECURITY_STRATEGY", "Enforce".as_ref()),
                ("ROS_SECURITY_KEYSTORE", store.as_os_str()),
                ("ROS_DOMAIN_ID", "0".as_ref()),
            ],
        );
        return;
    }
    let (done, finished) = mpsc::channel();
    std::thread::spawn(move || {
        start_nodes_racing_their_spinners();
        let _ = done.send(());
    });
    // The starts take about 7 s here; a deadlock is for ever.
    let deadline = Duration::from_secs(120);
    match finished.recv_timeout(deadline) {
        Ok(()) => {}
        Err(mpsc::RecvTimeoutError::Timeout) => panic!(
            "{STARTS} secure node starts did not finish within {deadline:?}: a lock-order deadlock between a \
             node's thread and its spinner"
        ),
        Err(mpsc::RecvTimeoutError::Disconnected) => panic!("the node starts failed (above)"),
    }
}
