//! The snake between two walls: a planar chain ([`PlanarChain`]) with a rubber half-ball foot at every
//! node, squeezed between the walls x = 0 (normal +x) and x = `gap` (normal −x), gravity along the
//! walls (−y), its joints driven by decentralised PD control to set points (the snake paper, section V, eqs. 5–6):
//!
//!   M(q) q̈ + h(q, q̇) = τ_PD + Σ_feet Jₙᵀ fₙ + Jₛᵀ fₜ,   τ_PD,j = k_p (q̄ⱼ − qⱼ) − k_d q̇ⱼ (joints only).
//!
//! Each foot is a ball of radius R centred on its node, turning freely on the node's axle (as the snake paper's
//! point contacts: a foot's contact moves with its node, and a link turning about a pressed foot does not
//! roll it). In contact with a wall it is pressed z = R − (distance of the node from the wall) deep and
//! the one contact law of `softcontact_contact` gives its forces:
//! - normal: fₙ = kₙ z^{3/2} + λ z^{3/2} ż (Hertz, with Hunt–Crossley damping λ), through the node;
//! - tangential, along the wall at the contact point: Walton's fₜ = kₜ √z δₜ or the incremental
//!   Mindlin–Deresiewicz law (`ContactModel::tangential_step`), capped at μfₙ (the foot then slides), plus
//!   a damping −λₜ z^{3/2} ẏ while it sticks; the displacement is the node's along the wall since the foot
//!   touched.

use nalgebra::{DVector, Vector2};
use serde::Serialize;
use softcontact_contact::{ContactError, ContactModel, TangentialMemory};
use softcontact_dynamics::PlanarChain;

/// Which wall a foot presses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Wall {
    /// x = 0, pushing the snake towards +x.
    Left,
    /// x = gap, pushing the snake towards −x.
    Right,
}

impl Wall {
    /// +1 for the left wall, −1 for the right: the wall's normal along x, into the gap.
    pub fn normal(self) -> f64 {
        match self {
            Wall::Left => 1.0,
            Wall::Right => -1.0,
        }
    }
}

/// The snake, its walls, feet and controller gains: everything but the state.
#[derive(Debug, Clone, PartialEq)]
pub struct Snake {
    pub chain: PlanarChain,
    /// Distance between the walls \[m\].
    pub gap: f64,
    /// The nodes that carry a foot (every node on the climbing snake).
    pub feet: Vec<usize>,
    /// The feet's radius R \[m\].
    pub foot_radius: f64,
    /// The feet's contact law: Hertz normal force (`hertz_walton`, its damping λ) and a tangential law.
    pub contact: ContactModel,
    /// λₜ of the tangential damping −λₜ z^{3/2} ṡ while a foot sticks [N s/m^{5/2}].
    pub tangential_damping: f64,
    /// Joint stiffness k_p [N m/rad] and damping k_d [N m s/rad] of the decentralised PD control.
    pub kp: f64,
    pub kd: f64,
    /// Constant external forces [N, world] at nodes (a pusher, a payload): none on the climbing snake.
    pub loads: Vec<(usize, Vector2<f64>)>,
}

/// A foot's memory: the wall it touches and its tangential law's state. Empty off the walls.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FootState {
    wall: Option<Wall>,
    memory: TangentialMemory,
}

/// What one foot feels from its wall.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct FootForce {
    pub wall: Option<Wall>,
    /// Depth z \[m\].
    pub depth: f64,
    /// fₙ ≥ 0 \[N\].
    pub normal: f64,
    /// fₜ \[N\], signed, positive up the wall (+y), on the snake.
    pub tangential: f64,
    /// |fₜ| = μfₙ: the foot slides.
    pub slides: bool,
}

impl FootForce {
    /// 1 − |fₜ|/(μfₙ): how far inside its friction cone the foot is (1 without tangential force, 0 at
    /// the cone, where it slides); `None` off the walls.
    pub fn cone_margin(&self, friction: f64) -> Option<f64> {
        (self.normal > 0.0).then(|| 1.0 - self.tangential.abs() / (friction * self.normal))
    }
}

/// The snake's state: coordinates, velocities and its feet's memories.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    pub q: Vec<f64>,
    pub dq: Vec<f64>,
    pub feet: Vec<FootState>,
}

impl State {
    /// At rest at `q`, no foot touching yet.
    pub fn at_rest(snake: &Snake, q: Vec<f64>) -> Self {
        State { dq: vec![0.0; q.len()], q, feet: vec![FootState::default(); snake.chain.nodes()] }
    }
}

impl Snake {
    /// The friction coefficient μ of the feet (0 without a tangential law).
    pub fn friction(&self) -> f64 {
        self.contact.tangential.map_or(0.0, |t| t.friction)
    }

    /// The generalized forces at (q, q̇) for joint set points `set_point` (one per joint), except
    /// −h(q, q̇): PD torques, loads and contact forces, the feet's memories advanced to q. Also each foot's
    /// force. A non-finite state is an error, never a force.
    pub fn applied_forces(
        &self,
        q: &[f64],
        dq: &[f64],
        set_point: &[f64],
        feet: &mut [FootState],
    ) -> Result<(DVector<f64>, Vec<FootForce>), ContactError> {
        let n = self.chain.dof();
        assert_eq!(set_point.len(), n - 3, "one set point per joint");
        if let Some(v) = q.iter().chain(dq).chain(set_point).find(|v| !v.is_finite()) {
            return Err(ContactError::NonFinite { name: "snake state or set point", value: *v });
        }
        let mut tau = DVector::zeros(n);
        for (j, target) in set_point.iter().enumerate() {
            tau[3 + j] = self.kp * (target - q[3 + j]) - self.kd * dq[3 + j];
        }
        let nodes = self.chain.node_positions(q);
        for (node, f) in &self.loads {
            self.chain.add_node_force(&nodes, *node, *f, &mut tau);
        }
        let mut out = Vec::with_capacity(feet.len());
        for (node, state) in feet.iter_mut().enumerate() {
            if !self.feet.contains(&node) {
                out.push(FootForce::default());
                continue;
            }
            let v = self.chain.node_velocity(&nodes, node, dq);
            let (force, world) = self.foot_force(state, nodes[node], v)?;
            self.chain.add_node_force(&nodes, node, world, &mut tau);
            out.push(force);
        }
        Ok((tau, out))
    }

    /// One foot at `p` moving at `v`: its force, and that force in the world.
    fn foot_force(
        &self,
        state: &mut FootState,
        p: Vector2<f64>,
        v: Vector2<f64>,
    ) -> Result<(FootForce, Vector2<f64>), ContactError> {
        let r = self.foot_radius;
        let wall = if p.x < r {
            Some(Wall::Left)
        } else if p.x > self.gap - r {
            Some(Wall::Right)
        } else {
            None
        };
        if wall != state.wall {
            *state = FootState { wall, ..FootState::default() };
        }
        let Some(wall) = wall else { return Ok((FootForce::default(), Vector2::zeros())) };
        let sign = wall.normal();
        let (depth, rate_in) = match wall {
            Wall::Left => (r - p.x, -v.x),
            Wall::Right => (p.x + r - self.gap, v.x),
        };
        let normal = self.contact.force(depth, rate_in)?;
        let (t, mut slides) =
            self.contact.tangential_step(&mut state.memory, [0.0, p.y, 0.0], [1.0, 0.0, 0.0], depth, normal)?;
        let mut tangential = t[1];
        if !slides {
            tangential -= self.tangential_damping * depth.powf(1.5) * v.y;
            let cap = self.friction() * normal;
            if tangential.abs() > cap {
                tangential = cap.copysign(tangential);
                slides = true;
            }
        }
        let force = FootForce { wall: Some(wall), depth, normal, tangential, slides };
        Ok((force, Vector2::new(sign * normal, tangential)))
    }

    /// q̈ at a state, and the feet's forces (the memories advanced).
    pub fn acceleration(
        &self,
        q: &[f64],
        dq: &[f64],
        set_point: &[f64],
        feet: &mut [FootState],
    ) -> Result<(DVector<f64>, Vec<FootForce>), ContactError> {
        let (tau, forces) = self.applied_forces(q, dq, set_point, feet)?;
        let (m, h) = self.chain.mass_matrix_and_nonlinear_effects(q, dq);
        let ddq = m.cholesky().expect("links with mass").solve(&(tau - h));
        if ddq.iter().all(|a| a.is_finite()) {
            Ok((ddq, forces))
        } else {
            Err(ContactError::NonFinite { name: "joint acceleration", value: f64::NAN })
        }
    }

    /// One step of `dt` (semi-implicit Euler: velocities first, then positions with the new velocities,
    /// which keeps the undamped contact oscillations from gaining energy). Returns the feet's forces at
    /// the start of the step.
    pub fn step(&self, state: &mut State, set_point: &[f64], dt: f64) -> Result<Vec<FootForce>, ContactError> {
        let (ddq, forces) = self.acceleration(&state.q, &state.dq, set_point, &mut state.feet)?;
        for i in 0..state.q.len() {
            state.dq[i] += dt * ddq[i];
            state.q[i] += dt * state.dq[i];
        }
        Ok(forces)
    }

    /// The feet's forces at a state, the memories left as they were.
    pub fn foot_forces(&self, state: &State, set_point: &[f64]) -> Result<Vec<FootForce>, ContactError> {
        let mut feet = state.feet.clone();
        Ok(self.applied_forces(&state.q, &state.dq, set_point, &mut feet)?.1)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use softcontact_contact::{Kind, Tangential};

    pub(crate) fn one_link(radius: f64) -> Snake {
        let mut contact = ContactModel::new(Kind::HertzWalton, 2.7e5, 0.0).unwrap();
        contact.tangential = Some(Tangential::walton(1.3e5, 0.9));
        Snake {
            chain: PlanarChain::uniform(1, 0.1, 0.2),
            gap: 0.5,
            feet: vec![0],
            foot_radius: radius,
            contact,
            tangential_damping: 0.0,
            kp: 0.0,
            kd: 0.0,
            loads: vec![(0, Vector2::new(-5.0, 0.0))],
        }
    }

    /// The generalized contact force does the work of the foot's forces: along any small motion,
    /// τᵀ dq = −fₙ dx + fₜ dy of a foot on the right wall, with the node's motion written out from the
    /// geometry (node 1 = (x + l cos θ, y + l sin θ)).
    #[test]
    fn contact_forces_do_the_work_of_the_foot() {
        let mut snake = one_link(0.01);
        snake.loads.clear();
        snake.feet = vec![1];
        let (l, theta) = (0.1, 0.3);
        // Node 1 1 mm into the right wall.
        snake.gap = l * f64::cos(theta) + 0.01 - 1e-3;
        let q = vec![0.0, 0.02, theta];
        let mut feet = vec![FootState::default(); 2];
        // Touch first, then displace: the tangential spring is stretched.
        snake.applied_forces(&[0.0, 0.0, theta], &[0.0; 3], &[], &mut feet).unwrap();
        let (tau, forces) = snake.applied_forces(&q, &[0.0; 3], &[], &mut feet).unwrap();
        let f = forces[1];
        assert_eq!(f.wall, Some(Wall::Right));
        assert!(f.normal > 0.0 && f.tangential < 0.0, "{f:?}");
        let dq = [1e-3, -2e-3, 0.5e-3];
        let node = [dq[0] - l * theta.sin() * dq[2], dq[1] + l * theta.cos() * dq[2]];
        let work = -f.normal * node[0] + f.tangential * node[1];
        let ours: f64 = tau.iter().zip(dq).map(|(t, d)| t * d).sum();
        assert!((ours - work).abs() < 1e-12 * work.abs().max(1.0), "{ours} vs {work}");
        assert!(tau[2].abs() > 1e-3, "the wall's force turns the link: {tau}");
    }

    #[test]
    fn a_non_finite_state_is_an_error() {
        let snake = one_link(0.01);
        let mut feet = vec![FootState::default(); 2];
        assert!(snake.acceleration(&[f64::NAN, 0.0, 0.0], &[0.0; 3], &[], &mut feet).is_err());
    }
}
