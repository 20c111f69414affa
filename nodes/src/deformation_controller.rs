//! The deformation controller node: the contact task of the force-control paper
//! ([`softcontact_control::contact_task`], the law and its equations) wired to ROS. One folder: the node's
//! policy (`node`: what is ticked, with which force, what the driver is told), its parameters
//! (`params`), its topics and action ([`interface`]) and the component that runs it in the driver's
//! 1 kHz process ([`component`]).

pub mod component;
pub mod interface;
mod node;
mod params;
pub mod standalone;

pub use component::InProcessController;
pub use interface::{ControllerInterface, PRESS_ACTION};
pub use node::{
    ControllerNode, JointSample, NodeCounters, Notices, Press, PressProgress, RETARE_LIFT, Reply, Retare, Silence, Step,
};
pub use params::{ModelUpdate, Params};
pub use softcontact_control::contact_task::{
    ARM_FORCE_SMOOTHING, AcrossReference, ControlError, ControllerConfig, ControllerState, DeformationController,
    EXPONENT_RANGE, FRICTION_COMPENSATED, FRICTION_COMPENSATED_JOINTS, FRICTION_COMPENSATION_SCALE, HOLD_FORCE_MARGIN,
    HOLD_LEAD, MAX_LATERAL, MAX_SENSOR_CORRECTION, MAX_TILT, MAX_TILT_RATE, MIN_MODEL_FORCE, MODEL_FORCE_EXCESS,
    MODEL_FORCE_EXCESS_MIN, OVER_COMMAND, OVER_COMMAND_MIN,
};
