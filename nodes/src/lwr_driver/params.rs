//! The `lwr_driver` node's parameters, declared once in [`NodeParams::declare`](crate::runtime::params::NodeParams).

use std::net::IpAddr;

use super::HOLD_STIFFNESS;

/// The `lwr_driver` node's parameters (config/lwr_driver.yaml), which the driver core reads as they are. What each means and the values it takes are
/// declared once, in `declare` (`NodeParams`), which checks them at start-up and describes them over ROS.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    pub fri_bind: std::net::SocketAddr,
    pub krc_address: Option<IpAddr>,
    pub new_session_after: f64,
    pub max_command_age: f64,
    pub watchdog_cycles: u64,
    pub hold_stiffness: [f64; 7],
    pub hold_damping: f64,
    pub velocity_margin: f64,
    pub limit_margin: f64,
    pub hold_release_cycles: u64,
    pub hold_max_preload: f64,
    pub monitor_only: bool,
    pub publish_joint_states: bool,
    pub publish_tf: bool,
    pub exit_after_silence: f64,
    pub dead_after: f64,
    pub use_sim_time: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            fri_bind: ([127, 0, 0, 1], 49938).into(),
            krc_address: None,
            new_session_after: 0.1,
            max_command_age: 0.02,
            watchdog_cycles: 5,
            hold_stiffness: [3000.0, 3000.0, 1000.0, 1500.0, 300.0, 150.0, 150.0],
            hold_damping: 0.7,
            velocity_margin: 0.9,
            limit_margin: 0.1,
            hold_release_cycles: 500,
            hold_max_preload: 0.05,
            monitor_only: false,
            publish_joint_states: false,
            publish_tf: true,
            exit_after_silence: 0.0,
            dead_after: 2.0,
            use_sim_time: false,
        }
    }
}

impl crate::runtime::params::NodeParams for Params {
    fn declare(&self, d: &mut crate::runtime::params::Declarations) {
        let bind = if self.fri_bind.ip().is_unspecified() {
            Err("listens on every network: give this PC's address on the robot network".to_string())
        } else {
            Ok(())
        };
        d.rule(
            "fri_bind",
            bind,
            "one address of this PC, never 0.0.0.0",
            "where the KRC sends its measurements (the KRC's FRIHOST:FRISOCK): this PC's address on the robot network",
        );
        let krc = match self.krc_address {
            Some(ip) if ip.is_unspecified() || ip.is_multicast() || ip == IpAddr::from([255, 255, 255, 255]) => {
                Err(format!("{ip} is not one machine's address"))
            }
            _ => Ok(()),
        };
        d.rule(
            "krc_address",
            krc,
            "one machine's address, or null",
            "the KRC's IP address; null: the first sender is pinned, every other address refused",
        );
        d.within(
            "new_session_after",
            self.new_session_after,
            (0.005, 10.0),
            "measurements resuming after this much silence start a new KRC session [s]",
        );
        d.within(
            "max_command_age",
            self.max_command_age,
            (0.001, 0.1),
            "a command answering a joint state older than this is refused, and one taken is applied no more once its stamp is older than this [s]",
        );
        d.integer(
            "watchdog_cycles",
            self.watchdog_cycles as i64,
            (1, 100),
            "a command older than this many cycles makes the driver hold position",
        );
        let stiffness =
            self.hold_stiffness.iter().zip(HOLD_STIFFNESS).enumerate().try_for_each(|(i, (k, (lo, hi)))| {
                if *k >= lo && *k <= hi {
                    Ok(())
                } else {
                    Err(format!("joint {}: {k} outside [{lo}, {hi}] N·m/rad", i + 1))
                }
            });
        let range = HOLD_STIFFNESS.iter().map(|(lo, hi)| format!("{lo} to {hi}")).collect::<Vec<_>>().join(", ");
        let range = format!("per joint: {range}");
        d.rule("hold_stiffness", stiffness, &range, "joint stiffness of the hold [N·m/rad]");
        d.above("hold_damping", self.hold_damping, (0.0, 1.0), "damping ratio of the hold");
        d.above(
            "velocity_margin",
            self.velocity_margin,
            (0.0, 1.0),
            "a joint beyond this fraction of its velocity limit is a fault: hold until the KRC starts a new session",
        );
        d.within(
            "limit_margin",
            self.limit_margin,
            (0.02, 0.5),
            "a joint in or heading into (50 ms ahead at its velocity) the last this much before its position limit is a fault: hold until the KRC starts a new session [rad]",
        );
        d.integer(
            "hold_release_cycles",
            self.hold_release_cycles as i64,
            (0, 10_000),
            "cycles over which a hold for a stale command fades out what its spring's preload cannot carry",
        );
        d.within("hold_max_preload", self.hold_max_preload, (0.0, 0.1), "largest offset of the hold's set point from the held position, per joint: how much of a stale command's torque the hold carries on, and the farthest it moves a joint should the surface vanish [rad]");
        d.any("monitor_only", "do not ask the KRL program to start command mode (monitor only)");
        d.any(
            "publish_joint_states",
            "also publish the joint positions on /joint_states as robot_state_publisher reads them (reliable, at the /tf rate)",
        );
        d.any(
            "publish_tf",
            "publish world → lwr_tool on /tf and lwr_tool → ft_sensor on /tf_static; false when robot_state_publisher publishes the URDF's tree from /joint_states (both would give lwr_tool two parents)",
        );
        d.within(
            "exit_after_silence",
            self.exit_after_silence,
            (0.0, 86_400.0),
            "stop after this long without a measurement (0: wait forever) [s]",
        );
        crate::runtime::liveness::declare_dead_after(
            d,
            self.dead_after,
            0.0,
            "torque commands silent this long while the KRC commands, after they flowed: the driver holds and reports the controller dead (it never exits while the KRC commands) [s]",
        );
        d.use_sim_time();
    }
}
