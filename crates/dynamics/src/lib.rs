//! Rigid-body kinematics and dynamics of a serial-chain robot described by a URDF.
//!
//! One [`Model`] (built once from the URDF, the robot's only description) and one [`Data`] workspace
//! (allocated once) serve the controller, the simulator and the drivers alike:
//!
//! - [`Model::forward_kinematics`], [`Model::frame_pose`], [`Model::frame_jacobian`] (world or local axes),
//!   [`Model::frame_velocity`], [`Model::frame_bias_acceleration`] (J̇q̇);
//! - [`Model::rnea`] (with an optional external wrench), [`Model::gravity_torques`],
//!   [`Model::nonlinear_effects`], [`Model::mass_matrix`] (CRBA), [`Model::forward_dynamics`]
//!   (CRBA + Cholesky), [`Model::kinetic_energy`], [`Model::potential_energy`];
//! - [`Model::control_terms`]: J, J̇q̇, M, M⁻¹ and h of one frame from a single kinematics pass.
//!
//! Conventions (those of Pinocchio, against which the crate is tested): world z up, gravity
//! [`model::STANDARD_GRAVITY`]; Jacobians and accelerations describe the frame's origin, linear rows
//! first; M q̈ + h = τ + Jᵀ w with w the wrench the environment exerts on the robot.
//!
//! No call allocates after [`Model::data`], so everything here may run in a 1 kHz loop.

pub mod arm_effects;
mod dynamics;
mod kinematics;
pub mod model;
pub mod planar;

pub use arm_effects::{ArmEffects, JointFriction, Payload};
pub use dynamics::{ControlTerms, ExternalWrench};
pub use kinematics::{Axes, Data, FrameMotion};
pub use model::{BodyInertia, Frame, FrameId, Joint, JointLimits, Model, fixed_subtree_inertia};
pub use planar::{PlanarChain, PlanarLink};

/// Why a robot description could not be used, or a dynamics query failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    #[error("cannot read URDF {path}: {message}")]
    Read { path: String, message: String },
    #[error("invalid URDF: {0}")]
    Parse(String),
    #[error("joint `{joint}` names link `{link}`, which the URDF does not define")]
    MissingLink { joint: String, link: String },
    #[error("the links do not form one tree (link `{link}` has more than one parent, or there is a cycle)")]
    NotATree { link: String },
    #[error("the URDF has several root links ({}); a robot description is one tree", .0.join(", "))]
    ManyRoots(Vec<String>),
    #[error("not a serial chain: link `{link}` has movable joints in more than one branch ({})", .branches.join(", "))]
    NotASerialChain { link: String, branches: Vec<String> },
    #[error("joint `{joint}` is {kind}; only revolute, continuous and fixed joints are supported")]
    UnsupportedJoint { joint: String, kind: String },
    #[error("joint `{joint}` has a zero or non-finite axis")]
    ZeroAxis { joint: String },
    #[error("the URDF has no movable joint")]
    NoMovableJoint,
    #[error("the body moved by joint `{joint}` has no inertial (zero mass): its dynamics would be singular")]
    NoInertial { joint: String },
    #[error(
        "link `{link}` has a non-physical inertial (negative or non-finite mass, or an inertia tensor that is not positive semi-definite or breaks the triangle inequality)"
    )]
    NonPhysicalInertia { link: String },
    #[error("no frame named `{name}`; the model's frames are: {known}")]
    UnknownFrame { name: String, known: String },
    #[error("the mass matrix is not positive definite at this state")]
    NotPositiveDefinite,
    #[error("invalid arm effects: {0}")]
    ArmEffects(String),
}

/// The KUKA LWR IV of this project (urdf/lwr4.urdf, compiled in so every tool has the same robot).
pub mod lwr4 {
    /// The URDF text of urdf/lwr4.urdf.
    pub const URDF: &str = include_str!("../../../urdf/lwr4.urdf");
    /// The hand's sole centre, where contact forces act.
    pub const TOOL_FRAME: &str = "lwr_tool";
    /// The sensing frame of the F/T sensor.
    pub const FT_SENSOR_FRAME: &str = "ft_sensor";
    pub const FLANGE_FRAME: &str = "lwr_flange";

    /// The model of urdf/lwr4.urdf.
    pub fn model() -> super::Model {
        super::Model::from_urdf_str(URDF).expect("urdf/lwr4.urdf is a valid serial chain")
    }

    /// The hand beyond the F/T sensor's sensing frame: mass properties in the `ft_sensor` frame.
    pub fn tool_load() -> super::BodyInertia {
        let robot = urdf_rs::read_from_string(URDF).expect("urdf/lwr4.urdf parses");
        super::fixed_subtree_inertia(&robot, FT_SENSOR_FRAME).expect("urdf/lwr4.urdf has the ft_sensor subtree")
    }
}
