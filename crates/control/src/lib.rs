//! Control of the normal force on a soft surface (the force-control paper): the contact task that ticks it
//! all at 1 kHz, with the paper's equations indexed to their items ([`contact_task`]), quintic references
//! ([`quintic`]), the deformation law that turns force commands into deformation accelerations ([`law`]),
//! task-space torques with null-space joint impedance ([`task`]), the inverse of an augmented contact model
//! ([`augmented`]) and the limits every torque passes ([`limits`]). Pure: the controller node wires it to ROS.
// Safety checks are written `!(x <= limit)` on purpose: they are true for NaN, which must be refused.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod augmented;
pub mod contact_task;
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
