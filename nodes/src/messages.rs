//! The messages the nodes publish, built from their structs' outputs: the node binaries publish them
//! over DDS and the in-process demo records them, so both say exactly the same thing.

use nalgebra::Isometry3;
use softcontact_dynamics::{FrameMotion, lwr4};
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::geometry_msgs::{
    Point, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Twist, TwistStamped, Vector3, Wrench,
    WrenchStamped,
};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{ContactState, ControllerState as ControllerStateMsg};
use softcontact_msgs::std_msgs::Header;
use softcontact_msgs::tf2_msgs::TFMessage;

use crate::contact_estimator::ContactStateOut;
use crate::deformation_controller::ControllerState;
use crate::lwr_driver::DriverOutput;

pub fn header(frame: &str, stamp: Time) -> Header {
    Header { stamp, frame_id: frame.into() }
}

fn vector(v: [f64; 3]) -> Vector3 {
    Vector3 { x: v[0], y: v[1], z: v[2] }
}

fn pose_parts(p: &Isometry3<f64>) -> (Vector3, Quaternion) {
    let (t, q) = (p.translation.vector, p.rotation);
    (vector([t.x, t.y, t.z]), Quaternion { x: q.i, y: q.j, z: q.k, w: q.w })
}

pub fn transform(parent: &str, child: &str, p: &Isometry3<f64>, stamp: Time) -> TransformStamped {
    let (translation, rotation) = pose_parts(p);
    TransformStamped {
        header: header(parent, stamp),
        child_frame_id: child.into(),
        transform: Transform { translation, rotation },
    }
}

/// /tf_static of the LWR driver: the sensing frame as seen from the tool, from the URDF.
pub fn tool_to_sensor_static(stamp: Time) -> TFMessage {
    let model = lwr4::model();
    let mut data = model.data();
    model.forward_kinematics(&mut data, &[0.0; 7]);
    let pose = |frame| model.frame_pose(&data, model.frame_id(frame).expect("the LWR model has its frames"));
    let tool_to_sensor = pose(lwr4::TOOL_FRAME).inverse() * pose(lwr4::FT_SENSOR_FRAME);
    TFMessage { transforms: vec![transform(lwr4::TOOL_FRAME, lwr4::FT_SENSOR_FRAME, &tool_to_sensor, stamp)] }
}

/// The LWR driver's 1 kHz topics for one measurement.
pub struct DriverMessages {
    pub joint_state: JointState,
    /// /lwr/external_torque: the KRC's external torque estimate in `effort`, stamped as the joint state.
    pub external_torque: JointState,
    pub ee_pose: PoseStamped,
    pub ee_twist: TwistStamped,
}

/// /tf: the tool in the world (published at most at [`crate::runtime::ros::TF_RATE`], off the 1 kHz loop).
pub fn tool_tf(tool_pose: &Isometry3<f64>, stamp: Time) -> TFMessage {
    TFMessage { transforms: vec![transform("world", lwr4::TOOL_FRAME, tool_pose, stamp)] }
}

/// What /lwr/joint_states say of the driver in `header.frame_id` (a joint state has no frame of its
/// own): the KRC session and whether the driver applies torque commands, as
/// `krc_session_<n>_<command|monitor|fault>` (`fault`: no torque until the operator restarts the KRL
/// program). The torque command echoes the header it answers, so the driver applies only commands of its
/// present session, and the controller approaches afresh when the session changes or torque stops.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriverSession {
    pub session: u32,
    pub commanding: bool,
    pub fault: bool,
}

impl DriverSession {
    const PREFIX: &str = "krc_session_";

    pub fn of(output: &crate::lwr_driver::DriverOutput) -> Self {
        let fault = matches!(output.waiting, Some(crate::lwr_driver::Waiting::Fault(_)));
        Self { session: output.session, commanding: output.torque_mode(), fault }
    }

    pub fn to_frame_id(self) -> String {
        let mode = match (self.commanding, self.fault) {
            (true, _) => "command",
            (false, true) => "fault",
            (false, false) => "monitor",
        };
        format!("{}{}_{}", Self::PREFIX, self.session, mode)
    }

    pub fn from_frame_id(frame_id: &str) -> Option<Self> {
        let (session, mode) = frame_id.strip_prefix(Self::PREFIX)?.split_once('_')?;
        let (commanding, fault) = match mode {
            "command" => (true, false),
            "monitor" => (false, false),
            "fault" => (false, true),
            _ => return None,
        };
        Some(Self { session: session.parse().ok()?, commanding, fault })
    }
}

impl DriverOutput {
    /// The messages of one measurement, with the tool's motion (`tool`) computed for it.
    pub fn messages(&self, joint_names: &[String], tool: &FrameMotion, stamp: Time) -> DriverMessages {
        let h = header("world", stamp);
        let session = DriverSession::of(self);
        let (t, q) = pose_parts(&tool.pose);
        let v = tool.twist;
        DriverMessages {
            joint_state: JointState {
                header: header(&session.to_frame_id(), stamp),
                name: joint_names.to_vec(),
                position: self.q.to_vec(),
                velocity: self.dq.to_vec(),
                effort: self.effort.to_vec(),
            },
            external_torque: JointState {
                header: header(&session.to_frame_id(), stamp),
                name: joint_names.to_vec(),
                position: vec![],
                velocity: vec![],
                effort: self.external_torque.to_vec(),
            },
            ee_pose: PoseStamped {
                header: h.clone(),
                pose: Pose { position: Point { x: t.x, y: t.y, z: t.z }, orientation: q },
            },
            ee_twist: TwistStamped {
                header: h,
                twist: Twist { linear: vector([v[0], v[1], v[2]]), angular: vector([v[3], v[4], v[5]]) },
            },
        }
    }
}

/// /joint_states for robot_state_publisher: the URDF's joint names and their measured positions.
pub fn robot_joint_state(joint_names: &[String], q: &[f64; 7], stamp: Time) -> JointState {
    JointState {
        header: header("", stamp),
        name: joint_names.to_vec(),
        position: q.to_vec(),
        velocity: vec![],
        effort: vec![],
    }
}

/// /ft_sensor/wrench and /ft_sensor/wrench_raw: a wrench in the sensing frame.
pub fn wrench(w: &[f64; 6], stamp: Time) -> WrenchStamped {
    WrenchStamped {
        header: header(lwr4::FT_SENSOR_FRAME, stamp),
        wrench: Wrench { force: vector([w[0], w[1], w[2]]), torque: vector([w[3], w[4], w[5]]) },
    }
}

/// /sim_arm/contact_wrench: the simulator's true contact force on the hand, world axes (the contact
/// acts at the tool point: no torque about it).
pub fn contact_wrench(force: &nalgebra::Vector3<f64>, stamp: Time) -> WrenchStamped {
    WrenchStamped {
        header: header("world", stamp),
        wrench: Wrench { force: vector([force.x, force.y, force.z]), torque: vector([0.0; 3]) },
    }
}

/// /lwr/joint_torque_command, stamped with the joint state it answers.
pub fn torque_command(joint_names: &[String], tau: &[f64; 7], answered: &Header) -> JointState {
    JointState {
        header: answered.clone(),
        name: joint_names.to_vec(),
        position: Vec::new(),
        velocity: Vec::new(),
        effort: tau.to_vec(),
    }
}

/// An empty /lwr/joint_torque_command: the controller has no torque for this joint state, and the
/// driver holds at once.
pub fn hold_request(joint_names: &[String], answered: &Header) -> JointState {
    JointState { effort: Vec::new(), ..torque_command(joint_names, &[0.0; 7], answered) }
}

/// /deformation_controller/state for the law's state of one tick.
pub fn controller_state(state: &ControllerState, stamp: Time) -> ControllerStateMsg {
    ControllerStateMsg {
        header: header("world", stamp),
        f_cmd: state.f_cmd,
        z_cmd: state.z_cmd,
        zdot_cmd: state.zdot_cmd,
        z: state.z,
        zdot: state.zdot,
        f: state.f,
        f_predicted: state.f_predicted,
        in_contact: state.in_contact,
        contact_lost: state.contact_lost,
        force_limited: state.force_limited,
    }
}

impl ContactStateOut {
    pub fn to_msg(&self, stamp: Time) -> ContactState {
        ContactState {
            header: header("world", stamp),
            deformation: self.deformation,
            deformation_rate: self.deformation_rate,
            normal_force: self.normal_force,
            in_contact: self.in_contact,
        }
    }
}
