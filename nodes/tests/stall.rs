//! A node stopped for 10 ms and resumed (Ctrl-Z and `fg`, strace, gdb: SIGSTOP then SIGCONT) must keep
//! its DDS. On Linux a thread blocked in epoll_wait returns EINTR when its process is continued, even
//! without a signal handler; RustDDS 0.15.1 ended its participant event loop and its discovery thread on
//! that error, so the node ran on, publishing into nothing and receiving nothing, for good, and said
//! nothing. The test stops and resumes the real node processes of the sensing chain over and over, in a
//! network namespace with only loopback, and checks that every stream flows afterwards and that the nodes
//! still discover a participant that joins after the stalls.

mod common;

use std::process::Child;
use std::time::{Duration, Instant};

use common::{INNER, Processes, in_isolated_namespace, signal, spawn};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::ContactState;
use softcontact_nodes::runtime::ros;

/// Joint states (the driver publishing) and estimator states (the estimator receiving the F/T node's
/// wrenches and the driver's poses, and publishing) received in `window`.
struct Flow {
    joint_states: ros2_client::Subscription<JointState>,
    states: ros2_client::Subscription<ContactState>,
}

impl Flow {
    fn new(node: &mut ros2_client::Node) -> Self {
        Flow {
            joint_states: ros::subscription_by_name(node, "/lwr/joint_states", ros::sensor_qos()).unwrap(),
            states: ros::subscription_by_name(node, "/contact_estimator/state", ros::sensor_qos()).unwrap(),
        }
    }

    fn count(&self, window: Duration) -> (usize, usize) {
        let (mut js, mut st) = (0, 0);
        let end = Instant::now() + window;
        while Instant::now() < end {
            while let Ok(Some(_)) = self.joint_states.take() {
                js += 1;
            }
            while let Ok(Some(_)) = self.states.take() {
                st += 1;
            }
            std::thread::sleep(Duration::from_micros(500));
        }
        (js, st)
    }
}

#[test]
fn nodes_keep_their_dds_through_sigstop_sigcont() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("nodes_keep_their_dds_through_sigstop_sigcont");
        return;
    }
    let mut node = ros::node("stall_test").unwrap();
    let flow = Flow::new(&mut node);
    let mut procs = Processes(vec![
        spawn(&common::workspace_binary("sim_arm"), &["-p", "surface:=dice", "-p", "seconds:=60"]),
        spawn(env!("CARGO_BIN_EXE_lwr_driver"), &["-p", "exit_after_silence:=1"]),
        spawn(env!("CARGO_BIN_EXE_ft_sensor"), &["-p", "exit_after_silence:=1"]),
        spawn(env!("CARGO_BIN_EXE_contact_estimator"), &[]),
    ]);

    // Up: joint states at ~1 kHz, estimator states at its state_rate (100 Hz).
    let start = Instant::now();
    loop {
        let (js, st) = flow.count(Duration::from_millis(500));
        if js > 300 && st > 20 {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(20), "graph did not come up: {js} joint states, {st} states");
    }
    let before = flow.count(Duration::from_secs(1));
    eprintln!("before the stalls, in 1 s: {} joint states, {} estimator states", before.0, before.1);

    // 20 stalls of 10 ms of the three DDS nodes, 100 to 290 ms apart (sim_arm is the robot: no DDS).
    let stalls = 20;
    for i in 0..stalls {
        let dds_nodes: Vec<&Child> = procs.0[1..].iter().collect();
        signal(&dds_nodes, libc::SIGSTOP);
        std::thread::sleep(Duration::from_millis(10));
        signal(&dds_nodes, libc::SIGCONT);
        flow.count(Duration::from_millis(100 + 10 * (i % 20)));
    }

    // Let the nodes settle (the driver holds after a gap), then every stream must be back at its rate.
    flow.count(Duration::from_secs(1));
    let after = flow.count(Duration::from_secs(2));
    eprintln!("after {stalls} stalls, in 2 s: {} joint states, {} estimator states", after.0, after.1);

    // A participant that joins now is discovered by the nodes (their discovery threads are alive).
    let mut late_node = ros::node("stall_test_late").unwrap();
    let late = Flow::new(&mut late_node);
    let joined = Instant::now();
    let mut late_counts = (0, 0);
    while joined.elapsed() < Duration::from_secs(6) && (late_counts.0 < 500 || late_counts.1 < 20) {
        let (js, st) = late.count(Duration::from_millis(250));
        late_counts = (late_counts.0 + js, late_counts.1 + st);
    }
    eprintln!(
        "a participant joining after the stalls: {} joint states, {} estimator states",
        late_counts.0, late_counts.1
    );

    for (c, name) in procs.0.iter_mut().zip(["sim_arm", "lwr_driver", "ft_sensor", "contact_estimator"]) {
        assert!(c.try_wait().unwrap().is_none(), "{name} still runs");
    }
    assert!(after.0 > 1000, "driver's joint states flow after the stalls: {} in 2 s", after.0);
    assert!(after.1 > 100, "estimator's states flow after the stalls: {} in 2 s", after.1);
    assert!(
        late_counts.0 >= 500 && late_counts.1 >= 20,
        "nodes discover a late participant: {} joint states, {} states",
        late_counts.0,
        late_counts.1
    );
}
