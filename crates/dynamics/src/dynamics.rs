//! Inverse dynamics (RNEA), the joint-space inertia matrix (CRBA), forward dynamics, energies, and the
//! set of terms one task-space control tick needs.
//!
//! Equation of motion of the chain: M(q) q̈ + h(q, q̇) = τ + Jᵀ w, with h = C(q, q̇) q̇ + g(q) and w an
//! external wrench acting on the robot. Recursions run in joint frames with origin-based body inertias
//! (mass, first moment, inertia about the joint origin), which is what makes them short.

use nalgebra::{DVector, Vector3, Vector6};

use crate::Error;
use crate::kinematics::{Axes, Data};
use crate::model::{FrameId, Model};

/// A wrench acting on the robot at a frame's origin, in world axes (e.g. a contact force on the hand).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExternalWrench {
    pub frame: FrameId,
    pub force: Vector3<f64>,
    /// Torque about the frame's origin.
    pub torque: Vector3<f64>,
}

/// What one task-space control tick needs at (q, q̇), for one frame. Borrowed from [`Data`].
#[derive(Debug)]
pub struct ControlTerms<'a> {
    /// Frame Jacobian, world axes.
    pub jacobian: &'a nalgebra::Matrix6xX<f64>,
    /// J̇q̇ of the frame, world axes.
    pub bias_acceleration: Vector6<f64>,
    pub mass_matrix: &'a nalgebra::DMatrix<f64>,
    pub mass_matrix_inverse: &'a nalgebra::DMatrix<f64>,
    /// h = C q̇ + g.
    pub nonlinear_effects: &'a DVector<f64>,
}

impl Model {
    /// Backward pass of the RNEA over the accelerations of a [`Model::velocity_pass`]: joint torques
    /// into `data.tau`.
    fn backward_pass(&self, data: &mut Data, external: Option<&ExternalWrench>) {
        let n = self.dof();
        let ext = external.and_then(|w| {
            let frame = self.frame(w.frame);
            frame.joint.map(|j| (j, frame.placement.translation.vector, w))
        });
        let mut f_child = Vector3::zeros();
        let mut n_child = Vector3::zeros();
        for i in (0..n).rev() {
            let body = &self.joints[i].body;
            let (w, wd, a) = (data.omega[i], data.omega_dot[i], data.accel[i]);
            let h = body.first_moment;
            let iw = body.inertia_origin * w;
            let mut f = body.mass * a + wd.cross(&h) + w.cross(&w.cross(&h));
            let mut m = body.inertia_origin * wd + w.cross(&iw) + h.cross(&a);
            if i + 1 < n {
                let e = &data.rel_rotation[i + 1];
                let fc = e * f_child;
                f += fc;
                m += e * n_child + self.joints[i + 1].translation.cross(&fc);
            }
            if let Some((j, r, wrench)) = ext
                && j == i
            {
                let rot = &data.rotation[i];
                let f_ext = rot.tr_mul(&wrench.force);
                f -= f_ext;
                m -= rot.tr_mul(&wrench.torque) + r.cross(&f_ext);
            }
            data.tau[i] = self.joints[i].axis.dot(&m);
            f_child = f;
            n_child = m;
        }
    }

    /// Inverse dynamics: τ = M q̈ + h − Jᵀ w, the torques that produce `ddq` at (q, q̇) under gravity
    /// and the external wrench. Result in `data.tau`.
    pub fn rnea<'d>(
        &self,
        data: &'d mut Data,
        q: &[f64],
        dq: &[f64],
        ddq: &[f64],
        external: Option<&ExternalWrench>,
    ) -> &'d DVector<f64> {
        self.check_len("dq", dq);
        self.check_len("ddq", ddq);
        self.forward_kinematics(data, q);
        self.velocity_pass(data, dq, Some(ddq), -self.gravity);
        self.backward_pass(data, external);
        &data.tau
    }

    /// Gravity torques g(q): what the motors must supply to hold the arm still.
    pub fn gravity_torques<'d>(&self, data: &'d mut Data, q: &[f64]) -> &'d DVector<f64> {
        self.forward_kinematics(data, q);
        for i in 0..self.dof() {
            data.omega[i] = Vector3::zeros();
            data.omega_dot[i] = Vector3::zeros();
            data.accel[i] = data.rotation[i].tr_mul(&-self.gravity);
        }
        self.backward_pass(data, None);
        &data.tau
    }

    /// Nonlinear effects h(q, q̇) = C(q, q̇) q̇ + g(q).
    pub fn nonlinear_effects<'d>(&self, data: &'d mut Data, q: &[f64], dq: &[f64]) -> &'d DVector<f64> {
        self.check_len("dq", dq);
        self.forward_kinematics(data, q);
        self.velocity_pass(data, dq, None, -self.gravity);
        self.backward_pass(data, None);
        &data.tau
    }

    /// CRBA on the kinematics already in `data`, in world axes: composite inertias (about the world
    /// origin) are plain sums from the tip down, and entry (j, i) is the moment about joint j's axis of
    /// the momentum (P, L) that a unit rate of joint i gives its composite: z_j·L − P·(z_j × o_j).
    fn crba_on_kinematics(&self, data: &mut Data) {
        if data.mass_matrix_fresh {
            return;
        }
        data.mass_matrix_fresh = true;
        let n = self.dof();
        let mut composite = crate::model::BodyInertia::ZERO;
        for i in (0..n).rev() {
            composite = composite.add(&self.joints[i].body.expressed_in_parent(&data.rotation[i], &data.origin[i]));
            data.composite[i] = composite;
            let z = data.rotation[i] * self.joints[i].axis;
            data.axis_world[i] = z;
            data.axis_moment[i] = z.cross(&data.origin[i]);
        }
        let m = data.mass_matrix.as_mut_slice();
        for i in 0..n {
            let c = &data.composite[i];
            let (z, o) = (data.axis_world[i], data.origin[i]);
            let p = z.cross(&(c.first_moment - c.mass * o));
            let l = c.inertia_origin * z - c.first_moment.cross(&z.cross(&o));
            for j in 0..=i {
                let mji = data.axis_world[j].dot(&l) - p.dot(&data.axis_moment[j]);
                m[j + i * n] = mji;
                m[i + j * n] = mji;
            }
        }
    }

    /// Joint-space inertia matrix M(q) (CRBA), full and symmetric, in `data.mass_matrix`.
    pub fn mass_matrix<'d>(&self, data: &'d mut Data, q: &[f64]) -> &'d nalgebra::DMatrix<f64> {
        self.forward_kinematics(data, q);
        self.crba_on_kinematics(data);
        &data.mass_matrix
    }

    /// Cholesky factorisation of `data.mass_matrix`, reusing the factor's storage (no allocation).
    fn factor_mass_matrix(&self, data: &mut Data) -> Result<(), Error> {
        if data.factor_fresh && data.cholesky.is_some() {
            return Ok(());
        }
        let storage = match data.cholesky.take() {
            Some(chol) => {
                let mut m = chol.unpack_dirty();
                m.copy_from(&data.mass_matrix);
                m
            }
            None => data.mass_matrix.clone(),
        };
        data.cholesky = nalgebra::Cholesky::new(storage);
        data.factor_fresh = data.cholesky.is_some();
        data.cholesky.as_ref().map(|_| ()).ok_or(Error::NotPositiveDefinite)
    }

    /// M⁻¹ from the factor of `data.mass_matrix`, into `data.mass_matrix_inverse`.
    fn invert_mass_matrix(&self, data: &mut Data) -> Result<(), Error> {
        self.factor_mass_matrix(data)?;
        data.mass_matrix_inverse.fill_with_identity();
        if let Some(chol) = data.cholesky.as_ref() {
            chol.solve_mut(&mut data.mass_matrix_inverse);
        }
        Ok(())
    }

    /// Inverse of the joint-space inertia matrix, M(q)⁻¹, in `data.mass_matrix_inverse`.
    pub fn mass_matrix_inverse<'d>(&self, data: &'d mut Data, q: &[f64]) -> Result<&'d nalgebra::DMatrix<f64>, Error> {
        self.forward_kinematics(data, q);
        self.crba_on_kinematics(data);
        self.invert_mass_matrix(data)?;
        Ok(&data.mass_matrix_inverse)
    }

    /// Forward dynamics: q̈ = M⁻¹ (τ + Jᵀ w − h), by CRBA and a Cholesky solve. Result in `data.ddq`.
    pub fn forward_dynamics<'d>(
        &self,
        data: &'d mut Data,
        q: &[f64],
        dq: &[f64],
        tau: &[f64],
        external: Option<&ExternalWrench>,
    ) -> Result<&'d DVector<f64>, Error> {
        self.check_len("dq", dq);
        self.check_len("tau", tau);
        self.forward_kinematics(data, q);
        self.velocity_pass(data, dq, None, -self.gravity);
        self.backward_pass(data, external);
        self.crba_on_kinematics(data);
        self.factor_mass_matrix(data)?;
        for ((ddq, tau), h) in data.ddq.iter_mut().zip(tau).zip(data.tau.iter()) {
            *ddq = tau - h;
        }
        if let Some(chol) = data.cholesky.as_ref() {
            chol.solve_mut(&mut data.ddq);
        }
        Ok(&data.ddq)
    }

    /// Kinetic energy ½ Σ (m v·v + 2 v·(ω×h) + ω·I ω) from the body velocities (not from M).
    pub fn kinetic_energy(&self, data: &mut Data, q: &[f64], dq: &[f64]) -> f64 {
        self.check_len("dq", dq);
        self.forward_kinematics(data, q);
        let (mut w, mut v) = (Vector3::zeros(), Vector3::zeros());
        let mut energy = 0.0;
        for (i, joint) in self.joints.iter().enumerate() {
            let rt = data.rel_rotation[i].transpose();
            v = rt * (v + w.cross(&joint.translation));
            w = rt * w + joint.axis * dq[i];
            let b = &joint.body;
            energy +=
                0.5 * (b.mass * v.dot(&v) + 2.0 * v.dot(&w.cross(&b.first_moment)) + w.dot(&(b.inertia_origin * w)));
        }
        energy
    }

    /// Potential energy of the moving bodies in gravity, zero at the world origin.
    pub fn potential_energy(&self, data: &mut Data, q: &[f64]) -> f64 {
        self.forward_kinematics(data, q);
        self.joints
            .iter()
            .enumerate()
            .map(|(i, j)| -self.gravity.dot(&(j.body.mass * data.origin[i] + data.rotation[i] * j.body.first_moment)))
            .sum()
    }

    /// Everything a task-space control tick needs for `frame` at (q, q̇), from one kinematics pass:
    /// J, J̇q̇, M, M⁻¹ and h.
    pub fn control_terms<'d>(
        &self,
        data: &'d mut Data,
        q: &[f64],
        dq: &[f64],
        frame: FrameId,
    ) -> Result<ControlTerms<'d>, Error> {
        self.check_len("dq", dq);
        self.forward_kinematics(data, q);
        let mut jacobian = std::mem::replace(&mut data.jacobian, nalgebra::Matrix6xX::zeros(0));
        self.frame_jacobian(data, frame, Axes::World, &mut jacobian);
        data.jacobian = jacobian;
        let base = -self.gravity;
        self.velocity_pass(data, dq, None, base);
        let bias_acceleration = self.frame_acceleration_from_pass(data, frame, base);
        self.backward_pass(data, None);
        self.crba_on_kinematics(data);
        self.invert_mass_matrix(data)?;
        Ok(ControlTerms {
            jacobian: &data.jacobian,
            bias_acceleration,
            mass_matrix: &data.mass_matrix,
            mass_matrix_inverse: &data.mass_matrix_inverse,
            nonlinear_effects: &data.tau,
        })
    }
}
