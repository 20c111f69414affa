//! The simulated cell: what stands in for the robot, the KRC and the Net F/T box when there is none. It is
//! not part of the product (`softcontact-nodes` does not depend on it); the product's nodes run against it
//! unchanged, over the same protocols.
//!
//! - [`cell`]: the lockstep cell in-process — the product's driver, F/T node, controller and estimator
//!   exchanging real FRI and RDT bytes with [`softcontact_sim::Simulator`] each 1 ms cycle, on one thread
//!   (tests, the demo, the loading-paths stage).
//! - [`sim_arm`]: the same simulator behind real sockets (FRI and RDT over UDP, the box's settings page
//!   over HTTP), the `sim_arm` node that `launch-scripts/sim.sh` starts.
// Safety checks are written `!(x <= limit)` on purpose: they are true for NaN, which must be refused.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cell;
pub mod sim_arm;

use softcontact_nodes::runtime::params::reference::{self, NodeReference};

/// Every node's parameter reference, the product's and the simulator's, in the order the docs list them:
/// what `softcontact params` prints and `docs/parameters.md` holds.
pub fn parameter_reference() -> Vec<NodeReference> {
    let mut nodes = reference::product_nodes();
    nodes.push(sim_arm::reference());
    nodes
}
