//! Control of the normal force on a soft surface (the force-control paper): quintic references ([`quintic`]), the
//! deformation law that turns force commands into deformation accelerations ([`law`]), and task-space
//! torques with null-space joint impedance ([`task`]). Pure: the controller node wires it to ROS.

pub mod augmented;
pub mod law;
pub mod limits;
pub mod quintic;
pub mod stage;
pub mod task;

pub use augmented::AugmentedInverse;
pub use law::{DeformationGains, deformation_acceleration, force_to_deformation};
pub use limits::{LimitError, Limits, TorqueLimiter};
pub use quintic::{Oscillation, Quintic, Reference, Segment, SetpointSequence, Trajectory};
pub use stage::{PositionStage, StageError};
pub use task::{Damping, TaskTorque, task_space_torque};
