//! The snake paper's climbing snake ("Frictional Compliance Model Development and Experiments for Snake
//! Robot Climbing", section V): a planar chain squeezed between two walls on compliant rubber feet, driven by
//! decentralised PD control to a sequence of set points; the equilibrium each set point reaches, its
//! stability with the contact law plugged into the dynamics, and a gait that climbs.
//!
//! - [`snake`]: the model (chain, walls, feet, gains) and its simulation;
//! - [`stability`]: equilibria found by settling and Newton, the linearised closed loop, eigenvalues;
//! - [`gait`]: the set points of a climbing gait and the climb, checked at every set point.
//!
//! Pure: no clocks, threads or files.

pub mod gait;
pub mod snake;
pub mod stability;

pub use gait::{Climb, ClimbConfig, SetPointReport, climb};
pub use snake::{FootForce, FootState, Snake, State, Wall};
pub use stability::{Settled, Stability, analyse, eigenvalues, linearize, refine, settle};

/// Why an analysis could not be done.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Contact(#[from] softcontact_contact::ContactError),
    #[error("{0}")]
    Analysis(String),
    #[error("invalid snake: {0}")]
    Config(String),
}
