//! A planar chain of rigid links with a floating base: the snake of the snake paper's section V ("Modeling and
//! Experimental Validation of a Compliant Contact Model …", the climbing robot between two walls).
//!
//! Coordinates q = [x, y, θ, q₁ … q_{N−1}]: node 0 (the first link's proximal end) at (x, y), the first
//! link at angle θ from the world x axis, qⱼ the angle of link j relative to link j−1 (positive
//! counter-clockwise). Link k's absolute angle is φₖ = θ + Σ_{j≤k} qⱼ; its nodes are k and k+1, its
//! centre of mass `com` along it from node k. Gravity acts along −y.
//!
//! The equations of motion are M(q) q̈ + h(q, q̇) = τ + Σ Jᵀ f (Pinocchio's convention, as the 3-D
//! [`crate::Model`]): with each link's centre-of-mass Jacobian Jₖ (2 × n) and angle row aₖ (∂φₖ/∂q̇),
//! M = Σ mₖ JₖᵀJₖ + Iₖ aₖaₖᵀ and h = Σ mₖ Jₖᵀ (J̇ₖq̇ + g ŷ); the planar angular term has no gyroscopic part
//! (aₖ is constant). These are the projected Newton–Euler equations, tested against Pinocchio built from
//! the same chain (PX, PY, RZ joints), finite differences of the Lagrangian and energy conservation.
//!
//! Unlike [`crate::Model`], these calls allocate their results: the snake is analysed offline.

use nalgebra::{DMatrix, DVector, Matrix2xX, Vector2};

use crate::model::STANDARD_GRAVITY;

/// One rigid link of a planar chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarLink {
    /// Distance between its two nodes \[m\].
    pub length: f64,
    pub mass: f64,
    /// Centre of mass along the link from its proximal node \[m\].
    pub com: f64,
    /// Moment of inertia about the centre of mass, about the plane's normal [kg m²].
    pub inertia: f64,
}

impl PlanarLink {
    /// A uniform rod.
    pub fn rod(length: f64, mass: f64) -> Self {
        PlanarLink { length, mass, com: 0.5 * length, inertia: mass * length * length / 12.0 }
    }
}

/// A planar chain with a floating base (x, y, θ) and a revolute joint between consecutive links.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarChain {
    pub links: Vec<PlanarLink>,
    /// Gravity's magnitude along −y [m/s²].
    pub gravity: f64,
}

/// Index of θ in q: the first of the angle coordinates.
const THETA: usize = 2;

impl PlanarChain {
    /// `n` equal rods (n ≥ 1) under standard gravity.
    pub fn uniform(n: usize, length: f64, mass: f64) -> Self {
        assert!(n >= 1, "a chain has at least one link");
        PlanarChain { links: vec![PlanarLink::rod(length, mass); n], gravity: -STANDARD_GRAVITY.z }
    }

    /// Number of coordinates: 3 for the base, one per joint.
    pub fn dof(&self) -> usize {
        self.links.len() + 2
    }

    /// Number of nodes (link ends).
    pub fn nodes(&self) -> usize {
        self.links.len() + 1
    }

    pub fn total_mass(&self) -> f64 {
        self.links.iter().map(|l| l.mass).sum()
    }

    fn check(&self, name: &str, v: &[f64]) {
        assert_eq!(v.len(), self.dof(), "{name} has {} entries, the chain has {} coordinates", v.len(), self.dof());
    }

    /// Absolute angle φₖ of every link.
    pub fn link_angles(&self, q: &[f64]) -> Vec<f64> {
        self.check("q", q);
        let mut phi = q[THETA];
        (0..self.links.len())
            .map(|k| {
                if k > 0 {
                    phi += q[THETA + k];
                }
                phi
            })
            .collect()
    }

    /// Absolute angular velocity φ̇ₖ of every link.
    fn link_rates(&self, dq: &[f64]) -> Vec<f64> {
        let mut w = 0.0;
        (0..self.links.len())
            .map(|k| {
                w += dq[THETA + k];
                w
            })
            .collect()
    }

    /// World position of every node.
    pub fn node_positions(&self, q: &[f64]) -> Vec<Vector2<f64>> {
        let phi = self.link_angles(q);
        let mut p = Vector2::new(q[0], q[1]);
        let mut out = vec![p];
        for (link, a) in self.links.iter().zip(&phi) {
            p += link.length * unit(*a);
            out.push(p);
        }
        out
    }

    /// World position of the point `along` \[m\] from node k on link k (k < N; `along` may be any length,
    /// e.g. the link's length for node k+1).
    pub fn point(&self, q: &[f64], link: usize, along: f64) -> Vector2<f64> {
        let phi = self.link_angles(q);
        let base = Vector2::new(q[0], q[1]);
        let nodes: Vector2<f64> = (0..link).map(|m| self.links[m].length * unit(phi[m])).sum();
        base + nodes + along * unit(phi[link])
    }

    /// Jacobian (2 × n, world axes) of the point `along` \[m\] from node k on link k: its velocity is J q̇.
    pub fn point_jacobian(&self, q: &[f64], link: usize, along: f64) -> Matrix2xX<f64> {
        let phi = self.link_angles(q);
        let mut j = Matrix2xX::zeros(self.dof());
        j[(0, 0)] = 1.0;
        j[(1, 1)] = 1.0;
        // Link m turns with every angle coordinate up to its own (θ and q₁ … q_m): each one swings the
        // lever from node m onwards.
        for (m, angle) in phi.iter().enumerate().take(link + 1) {
            let lever = if m == link { along } else { self.links[m].length };
            let swing = lever * perp(*angle);
            for c in THETA..=THETA + m {
                j[(0, c)] += swing.x;
                j[(1, c)] += swing.y;
            }
        }
        j
    }

    /// J̇q̇ of the same point: its acceleration when q̈ = 0 (the centripetal terms).
    pub fn point_bias_acceleration(&self, q: &[f64], dq: &[f64], link: usize, along: f64) -> Vector2<f64> {
        self.check("dq", dq);
        let (phi, w) = (self.link_angles(q), self.link_rates(dq));
        (0..=link)
            .map(|m| {
                let lever = if m == link { along } else { self.links[m].length };
                -lever * w[m] * w[m] * unit(phi[m])
            })
            .sum()
    }

    /// Velocity of node `node` given every node's position (from [`PlanarChain::node_positions`]): the
    /// base's, plus each upstream link's rate turning the node about that link's proximal node.
    pub fn node_velocity(&self, nodes: &[Vector2<f64>], node: usize, dq: &[f64]) -> Vector2<f64> {
        let mut v = Vector2::new(dq[0], dq[1]);
        for j in 0..node {
            let r = nodes[node] - nodes[j];
            v += dq[THETA + j] * Vector2::new(-r.y, r.x);
        }
        v
    }

    /// Adds to `tau` the generalized force of a force `f` [N, world] on node `node` (Jᵀf): `f` on the
    /// base's x and y, and on the angle of each link upstream of the node, f's moment about that link's
    /// proximal node.
    pub fn add_node_force(&self, nodes: &[Vector2<f64>], node: usize, f: Vector2<f64>, tau: &mut DVector<f64>) {
        tau[0] += f.x;
        tau[1] += f.y;
        for j in 0..node {
            tau[THETA + j] += (nodes[node] - nodes[j]).perp(&f);
        }
    }

    /// M(q) and h(q, q̇) together, each link's Jacobian computed once (what a simulation step needs).
    pub fn mass_matrix_and_nonlinear_effects(&self, q: &[f64], dq: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
        self.check("dq", dq);
        let (phi, w) = (self.link_angles(q), self.link_rates(dq));
        let n = self.dof();
        let (mut m, mut h) = (DMatrix::zeros(n, n), DVector::zeros(n));
        let mut j = Matrix2xX::zeros(n);
        for (k, link) in self.links.iter().enumerate() {
            // The centre of mass's Jacobian (columns of the link angles up to k) and J̇q̇.
            j.fill(0.0);
            j[(0, 0)] = 1.0;
            j[(1, 1)] = 1.0;
            let mut bias = Vector2::new(0.0, self.gravity);
            for (mm, angle) in phi.iter().enumerate().take(k + 1) {
                let lever = if mm == k { link.com } else { self.links[mm].length };
                let swing = lever * perp(*angle);
                for c in THETA..=THETA + mm {
                    j[(0, c)] += swing.x;
                    j[(1, c)] += swing.y;
                }
                bias -= lever * w[mm] * w[mm] * unit(*angle);
            }
            m += link.mass * j.transpose() * &j;
            // The link's angle row aₖ: ones on θ … q_k.
            for a in THETA..=THETA + k {
                for b in THETA..=THETA + k {
                    m[(a, b)] += link.inertia;
                }
            }
            h += link.mass * j.transpose() * bias;
        }
        (m, h)
    }

    /// The row aₖ with φ̇ₖ = aₖ q̇.
    fn angle_row(&self, k: usize) -> DVector<f64> {
        DVector::from_fn(self.dof(), |c, _| if (THETA..=THETA + k).contains(&c) { 1.0 } else { 0.0 })
    }

    /// Joint-space inertia matrix M(q) (symmetric, positive definite).
    pub fn mass_matrix(&self, q: &[f64]) -> DMatrix<f64> {
        let n = self.dof();
        let mut m = DMatrix::zeros(n, n);
        for (k, link) in self.links.iter().enumerate() {
            let j = self.point_jacobian(q, k, link.com);
            let a = self.angle_row(k);
            m += link.mass * j.transpose() * &j + link.inertia * &a * a.transpose();
        }
        m
    }

    /// h(q, q̇) = C(q, q̇) q̇ + G(q): Coriolis, centrifugal and gravity forces (Pinocchio's nle).
    pub fn nonlinear_effects(&self, q: &[f64], dq: &[f64]) -> DVector<f64> {
        let mut h = DVector::zeros(self.dof());
        for (k, link) in self.links.iter().enumerate() {
            let j = self.point_jacobian(q, k, link.com);
            let acc = self.point_bias_acceleration(q, dq, k, link.com) + Vector2::new(0.0, self.gravity);
            h += link.mass * j.transpose() * acc;
        }
        h
    }

    /// G(q) = ∂V/∂q.
    pub fn gravity_forces(&self, q: &[f64]) -> DVector<f64> {
        self.nonlinear_effects(q, &vec![0.0; self.dof()])
    }

    /// q̈ = M⁻¹ (τ − h).
    pub fn forward_dynamics(&self, q: &[f64], dq: &[f64], tau: &DVector<f64>) -> DVector<f64> {
        let (m, h) = self.mass_matrix_and_nonlinear_effects(q, dq);
        let rhs = tau - h;
        m.cholesky().expect("the mass matrix of a chain with massive links is positive definite").solve(&rhs)
    }

    pub fn kinetic_energy(&self, q: &[f64], dq: &[f64]) -> f64 {
        let v = DVector::from_column_slice(dq);
        0.5 * v.dot(&(self.mass_matrix(q) * &v))
    }

    /// Potential energy of gravity, zero at y = 0.
    pub fn potential_energy(&self, q: &[f64]) -> f64 {
        self.links.iter().enumerate().map(|(k, l)| l.mass * self.gravity * self.point(q, k, l.com).y).sum()
    }
}

fn unit(a: f64) -> Vector2<f64> {
    Vector2::new(a.cos(), a.sin())
}

/// d unit(a)/da.
fn perp(a: f64) -> Vector2<f64> {
    Vector2::new(-a.sin(), a.cos())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain() -> PlanarChain {
        let mut c = PlanarChain::uniform(4, 0.1, 0.2);
        // Unequal links, so that an index mixed up shows.
        c.links[1] = PlanarLink { length: 0.12, mass: 0.25, com: 0.07, inertia: 4e-4 };
        c.links[3].com = 0.03;
        c
    }

    fn state(seed: u64) -> (Vec<f64>, Vec<f64>) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
        let q = (0..6).map(|_| rng.random_range(-2.0..2.0)).collect();
        let dq = (0..6).map(|_| rng.random_range(-3.0..3.0)).collect();
        (q, dq)
    }

    /// Lagrangian L = T − V, for its finite differences.
    fn lagrangian(c: &PlanarChain, q: &[f64], dq: &[f64]) -> f64 {
        c.kinetic_energy(q, dq) - c.potential_energy(q)
    }

    #[test]
    fn the_node_jacobian_is_the_derivative_of_the_node_positions() {
        let c = chain();
        for seed in 0..5 {
            let (q, _) = state(seed);
            for link in 0..4 {
                let j = c.point_jacobian(&q, link, c.links[link].length);
                for col in 0..6 {
                    let h = 1e-6;
                    let (mut a, mut b) = (q.clone(), q.clone());
                    a[col] += h;
                    b[col] -= h;
                    let fd = (c.node_positions(&a)[link + 1] - c.node_positions(&b)[link + 1]) / (2.0 * h);
                    assert!((fd - j.column(col)).norm() < 1e-8, "link {link} column {col}: {fd} vs {}", j.column(col));
                }
            }
        }
    }

    /// The one-pass terms, the node forces and velocities agree with M, h and the node Jacobians.
    #[test]
    fn the_fast_terms_agree_with_the_jacobians() {
        let c = chain();
        for seed in 0..5 {
            let (q, dq) = state(seed);
            let (m, h) = c.mass_matrix_and_nonlinear_effects(&q, &dq);
            assert!((&m - c.mass_matrix(&q)).amax() < 1e-12 && (&h - c.nonlinear_effects(&q, &dq)).amax() < 1e-12);
            let nodes = c.node_positions(&q);
            let f = Vector2::new(1.3, -0.7);
            for node in 0..c.nodes() {
                let (link, along) = if node == 0 { (0, 0.0) } else { (node - 1, c.links[node - 1].length) };
                let j = c.point_jacobian(&q, link, along);
                let mut tau = DVector::zeros(6);
                c.add_node_force(&nodes, node, f, &mut tau);
                assert!((&tau - j.transpose() * f).amax() < 1e-12, "node {node}");
                let v = c.node_velocity(&nodes, node, &dq);
                assert!((v - &j * DVector::from_column_slice(&dq)).amax() < 1e-12, "node {node}");
            }
        }
    }

    /// Lagrange's equations by finite differences, independent of the Newton–Euler projection: the
    /// generalized momentum p = ∂L/∂q̇ gives M (its Jacobian in q̇), and
    /// h = d/dt(∂L/∂q̇)|_{q̈=0} − ∂L/∂q = (∂p/∂q) q̇ − ∂L/∂q.
    #[test]
    fn mass_matrix_and_nonlinear_effects_follow_lagranges_equations() {
        let c = chain();
        let n = c.dof();
        let h = 1e-5;
        for seed in 0..5 {
            let (q, dq) = state(seed);
            let momentum = |q: &[f64], dq: &[f64]| -> DVector<f64> {
                DVector::from_fn(n, |i, _| {
                    let (mut a, mut b) = (dq.to_vec(), dq.to_vec());
                    a[i] += h;
                    b[i] -= h;
                    (lagrangian(&c, q, &a) - lagrangian(&c, q, &b)) / (2.0 * h)
                })
            };
            let m = c.mass_matrix(&q);
            let p = momentum(&q, &dq);
            assert!((&m * DVector::from_column_slice(&dq) - &p).amax() < 1e-7, "p = M q̇");
            let mut expected = DVector::zeros(n);
            for i in 0..n {
                let (mut a, mut b) = (q.clone(), q.clone());
                a[i] += h;
                b[i] -= h;
                expected += (momentum(&a, &dq) - momentum(&b, &dq)) / (2.0 * h) * dq[i];
                expected[i] -= (lagrangian(&c, &a, &dq) - lagrangian(&c, &b, &dq)) / (2.0 * h);
            }
            let got = c.nonlinear_effects(&q, &dq);
            assert!((&got - &expected).amax() < 1e-5 * expected.amax().max(1.0), "h {got} vs {expected}");
        }
    }

    /// Free motion without damping keeps T + V: an RK4 run of 1 s loses under 1e-8 of it.
    #[test]
    fn free_motion_conserves_energy() {
        let c = chain();
        let (mut q, mut dq) = state(7);
        let energy = |q: &[f64], dq: &[f64]| c.kinetic_energy(q, dq) + c.potential_energy(q);
        let e0 = energy(&q, &dq);
        let zero = DVector::zeros(6);
        let f = |q: &[f64], dq: &[f64]| c.forward_dynamics(q, dq, &zero);
        let dt = 1e-4;
        for _ in 0..10_000 {
            let add = |x: &[f64], d: &[f64], s: f64| -> Vec<f64> { x.iter().zip(d).map(|(a, b)| a + s * b).collect() };
            let k1v = f(&q, &dq);
            let (q2, v2) = (add(&q, &dq, dt / 2.0), add(&dq, k1v.as_slice(), dt / 2.0));
            let k2v = f(&q2, &v2);
            let (q3, v3) = (add(&q, &v2, dt / 2.0), add(&dq, k2v.as_slice(), dt / 2.0));
            let k3v = f(&q3, &v3);
            let (q4, v4) = (add(&q, &v3, dt), add(&dq, k3v.as_slice(), dt));
            let k4v = f(&q4, &v4);
            for i in 0..6 {
                q[i] += dt / 6.0 * (dq[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
                dq[i] += dt / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
            }
        }
        let e1 = energy(&q, &dq);
        assert!((e1 - e0).abs() < 1e-8 * e0.abs().max(1.0), "energy {e0} → {e1}");
    }
}
