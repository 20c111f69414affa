//! Every topic of the graph, declared once: its name, its message type and how its publisher delivers it
//! (docs/architecture.md, "The ROS 2 graph"). Nodes, recorders and tools take these instead of strings, so
//! a name or a type cannot differ between the writer and a reader.

use std::marker::PhantomData;

use crate::RosType;
use crate::diagnostic_msgs::DiagnosticArray;
use crate::geometry_msgs::{PoseStamped, TwistStamped, WrenchStamped};
use crate::rosgraph_msgs::Clock;
use crate::sensor_msgs::JointState;
use crate::softcontact_msgs::{ContactModel, ContactState, ControllerState, ForceCommand};
use crate::tf2_msgs::TFMessage;

/// How a topic's publisher offers its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Best effort, newest only: the 1 kHz streams.
    Sensor,
    /// Reliable, volatile: commands, models, diagnostics.
    Reliable,
    /// Reliable, transient local: late joiners get the last sample (/tf_static).
    Latched,
}

/// A topic: its ROS 2 name, its message type `M` and its [`Delivery`].
#[derive(Debug)]
pub struct Topic<M> {
    pub name: &'static str,
    pub delivery: Delivery,
    message: PhantomData<fn() -> M>,
}

impl<M> Topic<M> {
    const fn new(name: &'static str, delivery: Delivery) -> Self {
        Topic { name, delivery, message: PhantomData }
    }
}

impl<M: RosType> Topic<M> {
    /// The topic without its type parameter, for lists of topics of several types.
    pub fn described(&self) -> Described {
        Described { name: self.name, type_path: M::type_path(), delivery: self.delivery }
    }
}

/// A topic's name, type (`pkg/msg/Name`) and delivery.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Described {
    pub name: &'static str,
    pub type_path: String,
    pub delivery: Delivery,
}

pub const JOINT_STATES: Topic<JointState> = Topic::new("/lwr/joint_states", Delivery::Sensor);
/// The joint positions as robot_state_publisher reads them (reliable, at the /tf rate), when the driver's
/// `publish_joint_states` is set.
pub const ROBOT_JOINT_STATES: Topic<JointState> = Topic::new("/joint_states", Delivery::Reliable);
/// The URDF the driver's kinematics and dynamics use, latched.
pub const ROBOT_DESCRIPTION: Topic<crate::std_msgs::String> = Topic::new("/robot_description", Delivery::Latched);
pub const JOINT_TORQUE_COMMAND: Topic<JointState> = Topic::new("/lwr/joint_torque_command", Delivery::Reliable);
pub const EXTERNAL_TORQUE: Topic<JointState> = Topic::new("/lwr/external_torque", Delivery::Sensor);
pub const EE_POSE: Topic<PoseStamped> = Topic::new("/lwr/ee_pose", Delivery::Sensor);
pub const EE_TWIST: Topic<TwistStamped> = Topic::new("/lwr/ee_twist", Delivery::Sensor);
pub const TF: Topic<TFMessage> = Topic::new("/tf", Delivery::Reliable);
pub const TF_STATIC: Topic<TFMessage> = Topic::new("/tf_static", Delivery::Latched);
pub const WRENCH_RAW: Topic<WrenchStamped> = Topic::new("/ft_sensor/wrench_raw", Delivery::Sensor);
pub const WRENCH: Topic<WrenchStamped> = Topic::new("/ft_sensor/wrench", Delivery::Sensor);
pub const TARE: Topic<WrenchStamped> = Topic::new("/ft_sensor/tare", Delivery::Reliable);
pub const CONTACT_MODEL: Topic<ContactModel> = Topic::new("/contact_estimator/model", Delivery::Reliable);
pub const CONTACT_STATE: Topic<ContactState> = Topic::new("/contact_estimator/state", Delivery::Sensor);
pub const FORCE_COMMAND: Topic<ForceCommand> = Topic::new("/deformation_controller/force_command", Delivery::Reliable);
pub const CONTROLLER_STATE: Topic<ControllerState> = Topic::new("/deformation_controller/state", Delivery::Sensor);
pub const DIAGNOSTICS: Topic<DiagnosticArray> = Topic::new("/diagnostics", Delivery::Reliable);
pub const CONTACT_WRENCH: Topic<WrenchStamped> = Topic::new("/sim_arm/contact_wrench", Delivery::Sensor);
pub const CLOCK: Topic<Clock> = Topic::new("/clock", Delivery::Reliable);

/// The F/T node's software tare (std_srvs/Trigger).
pub const FT_BIAS_SERVICE: &str = "/ft_sensor/bias";
/// The controller's re-tare: lift off, tare, approach again (std_srvs/Trigger).
pub const RETARE_SERVICE: &str = "/deformation_controller/retare";
/// The controller's force goal (softcontact_msgs/action/PressForce).
pub const PRESS_ACTION: &str = "/deformation_controller/press";

/// The graph's topics that recordings carry and `softcontact record` subscribes to by default.
pub fn recorded() -> [Described; 14] {
    [
        JOINT_STATES.described(),
        JOINT_TORQUE_COMMAND.described(),
        EE_POSE.described(),
        EE_TWIST.described(),
        TF.described(),
        TF_STATIC.described(),
        WRENCH_RAW.described(),
        WRENCH.described(),
        TARE.described(),
        CONTACT_MODEL.described(),
        CONTACT_STATE.described(),
        FORCE_COMMAND.described(),
        CONTROLLER_STATE.described(),
        DIAGNOSTICS.described(),
    ]
}
