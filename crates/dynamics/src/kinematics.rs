//! Forward kinematics, frame Jacobians and the bias acceleration J̇q̇.
//!
//! Every algorithm first brings [`Data`] to the joint positions q: the relative rotation of each joint
//! and the world pose of each joint frame. Work stays in 3-vectors and 3×3 matrices; `Data` is
//! allocated once, so none of this allocates.

use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Matrix6xX, Rotation3, Translation3, UnitQuaternion, Vector3, Vector6,
};

use crate::model::{FrameId, Model};

/// Which axes a Jacobian's rows are expressed in. Both describe the velocity of the frame's origin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axes {
    /// World axes (Pinocchio's LOCAL_WORLD_ALIGNED).
    World,
    /// The frame's own axes (Pinocchio's LOCAL).
    Local,
}

/// Preallocated workspace of one model: kinematic state of every joint and the outputs of the
/// algorithms. Make it with [`Model::data`] and reuse it.
#[derive(Debug, Clone)]
pub struct Data {
    /// Rotation of joint i's frame in its parent's frame, at the current q.
    pub(crate) rel_rotation: Vec<Matrix3<f64>>,
    /// World rotation and origin of joint i's frame.
    pub(crate) rotation: Vec<Matrix3<f64>>,
    pub(crate) origin: Vec<Vector3<f64>>,
    // Per-joint recursion state, joint frame coordinates.
    pub(crate) omega: Vec<Vector3<f64>>,
    pub(crate) omega_dot: Vec<Vector3<f64>>,
    pub(crate) accel: Vec<Vector3<f64>>,
    pub(crate) composite: Vec<crate::model::BodyInertia>,
    /// World axis z of each joint and its moment z × o about the world origin (CRBA).
    pub(crate) axis_world: Vec<Vector3<f64>>,
    pub(crate) axis_moment: Vec<Vector3<f64>>,
    /// Joint torques of the last RNEA-family call (rnea, gravity, nonlinear effects).
    pub(crate) tau: DVector<f64>,
    /// Joint-space inertia matrix (full, symmetric) of the last CRBA.
    pub(crate) mass_matrix: DMatrix<f64>,
    /// Inverse of the mass matrix of the last [`Model::control_terms`] call.
    pub(crate) mass_matrix_inverse: DMatrix<f64>,
    /// Joint accelerations of the last forward dynamics.
    pub(crate) ddq: DVector<f64>,
    /// Frame Jacobian of the last [`Model::control_terms`] call.
    pub(crate) jacobian: Matrix6xX<f64>,
    pub(crate) cholesky: Option<nalgebra::Cholesky<f64, nalgebra::Dyn>>,
    /// The joint positions the kinematics above were computed for: algorithms called again at the same
    /// q (bit for bit) reuse them instead of recomputing sines and rotations.
    kinematics_q: Vec<f64>,
    /// `mass_matrix` and `cholesky` belong to the current kinematics (reset whenever FK recomputes).
    pub(crate) mass_matrix_fresh: bool,
    pub(crate) factor_fresh: bool,
}

impl Data {
    pub(crate) fn new(n: usize) -> Self {
        let v = vec![Vector3::zeros(); n];
        Self {
            rel_rotation: vec![Matrix3::identity(); n],
            rotation: vec![Matrix3::identity(); n],
            origin: v.clone(),
            omega: v.clone(),
            omega_dot: v.clone(),
            accel: v.clone(),
            axis_world: v.clone(),
            axis_moment: v,
            composite: vec![crate::model::BodyInertia::ZERO; n],
            tau: DVector::zeros(n),
            mass_matrix: DMatrix::zeros(n, n),
            mass_matrix_inverse: DMatrix::zeros(n, n),
            ddq: DVector::zeros(n),
            jacobian: Matrix6xX::zeros(n),
            cholesky: nalgebra::Cholesky::new(DMatrix::identity(n, n)),
            kinematics_q: vec![f64::NAN; n],
            mass_matrix_fresh: false,
            factor_fresh: false,
        }
    }
}

/// Rotation by an angle about a joint's unit axis, from the angle's sine and cosine: Rodrigues'
/// formula, with the coordinate axes of most URDFs written out (a third of the arithmetic).
#[inline(always)]
fn axis_rotation(axis: &Vector3<f64>, sin: f64, cos: f64) -> Matrix3<f64> {
    let (x, y, z) = (axis.x, axis.y, axis.z);
    if x == 0.0 && y == 0.0 {
        let s = sin * z;
        return Matrix3::new(cos, -s, 0.0, s, cos, 0.0, 0.0, 0.0, 1.0);
    }
    if x == 0.0 && z == 0.0 {
        let s = sin * y;
        return Matrix3::new(cos, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, cos);
    }
    if y == 0.0 && z == 0.0 {
        let s = sin * x;
        return Matrix3::new(1.0, 0.0, 0.0, 0.0, cos, -s, 0.0, s, cos);
    }
    let t = 1.0 - cos;
    Matrix3::new(
        t * x * x + cos,
        t * x * y - sin * z,
        t * x * z + sin * y,
        t * x * y + sin * z,
        t * y * y + cos,
        t * y * z - sin * x,
        t * x * z - sin * y,
        t * y * z + sin * x,
        t * z * z + cos,
    )
}

/// Where a frame is and how it moves: its pose in the world and its twist (world axes, linear then
/// angular).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMotion {
    pub pose: Isometry3<f64>,
    pub twist: Vector6<f64>,
}

impl FrameMotion {
    /// The origin's linear velocity.
    pub fn linear(&self) -> Vector3<f64> {
        self.twist.fixed_rows::<3>(0).into_owned()
    }

    /// The frame's angular velocity.
    pub fn angular(&self) -> Vector3<f64> {
        self.twist.fixed_rows::<3>(3).into_owned()
    }
}

impl Model {
    /// A workspace sized for this model.
    pub fn data(&self) -> Data {
        Data::new(self.dof())
    }

    pub(crate) fn check_len(&self, name: &str, v: &[f64]) {
        assert_eq!(v.len(), self.dof(), "{name} has {} entries, the model has {} joints", v.len(), self.dof());
    }

    /// Places every joint frame for joint positions `q`.
    pub fn forward_kinematics(&self, data: &mut Data, q: &[f64]) {
        self.check_len("q", q);
        if data.kinematics_q.iter().zip(q).all(|(a, b)| a.to_bits() == b.to_bits()) {
            return;
        }
        data.kinematics_q.copy_from_slice(q);
        data.mass_matrix_fresh = false;
        data.factor_fresh = false;
        let mut parent_rot = Matrix3::identity();
        let mut parent_origin = Vector3::zeros();
        for (i, joint) in self.joints.iter().enumerate() {
            let (s, c) = q[i].sin_cos();
            let about_axis = axis_rotation(&joint.axis, s, c);
            let rel = if joint.rotation_is_identity { about_axis } else { joint.rotation * about_axis };
            let origin = parent_origin + parent_rot * joint.translation;
            parent_rot *= rel;
            parent_origin = origin;
            data.rel_rotation[i] = rel;
            data.rotation[i] = parent_rot;
            data.origin[i] = origin;
        }
    }

    /// World rotation and position of a frame, after [`Model::forward_kinematics`].
    fn frame_rotation_position(&self, data: &Data, frame: FrameId) -> (Matrix3<f64>, Vector3<f64>) {
        let f = self.frame(frame);
        let (r, t) = (f.placement.rotation.to_rotation_matrix().into_inner(), f.placement.translation.vector);
        match f.joint {
            None => (r, t),
            Some(j) => (data.rotation[j] * r, data.origin[j] + data.rotation[j] * t),
        }
    }

    /// Pose of a frame in the world, after [`Model::forward_kinematics`].
    pub fn frame_pose(&self, data: &Data, frame: FrameId) -> Isometry3<f64> {
        let (r, p) = self.frame_rotation_position(data, frame);
        Isometry3::from_parts(
            Translation3::from(p),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
        )
    }

    /// Geometric Jacobian of a frame's origin (rows: linear x y z, angular x y z) into `out`, after
    /// [`Model::forward_kinematics`]. Columns of joints that do not move the frame are zero.
    pub fn frame_jacobian(&self, data: &Data, frame: FrameId, axes: Axes, out: &mut Matrix6xX<f64>) {
        assert_eq!(out.ncols(), self.dof(), "Jacobian needs {} columns", self.dof());
        out.fill(0.0);
        let (rot, p) = self.frame_rotation_position(data, frame);
        let Some(last) = self.frame(frame).joint else { return };
        for j in 0..=last {
            let z = data.rotation[j] * self.joints[j].axis;
            let mut lin = z.cross(&(p - data.origin[j]));
            let mut ang = z;
            if axes == Axes::Local {
                lin = rot.tr_mul(&lin);
                ang = rot.tr_mul(&ang);
            }
            out.fixed_view_mut::<3, 1>(0, j).copy_from(&lin);
            out.fixed_view_mut::<3, 1>(3, j).copy_from(&ang);
        }
    }

    /// Forward pass of velocities and accelerations: for each joint, angular velocity ω, angular
    /// acceleration ω̇ and classical linear acceleration of its origin, in its own frame. `base_accel`
    /// is the world acceleration imposed on the base (−g to fold gravity in, zero for pure kinematics).
    /// Needs [`Model::forward_kinematics`] first.
    pub(crate) fn velocity_pass(&self, data: &mut Data, dq: &[f64], ddq: Option<&[f64]>, base_accel: Vector3<f64>) {
        let mut w = Vector3::zeros();
        let mut wd = Vector3::zeros();
        let mut a = base_accel;
        for (i, joint) in self.joints.iter().enumerate() {
            let rt = data.rel_rotation[i].transpose();
            let p = &joint.translation;
            // The joint origin lies on the parent body: its acceleration is the parent's rigid motion.
            let a_i = rt * (a + wd.cross(p) + w.cross(&w.cross(p)));
            let w_in = rt * w;
            let w_i = w_in + joint.axis * dq[i];
            let mut wd_i = rt * wd + w_in.cross(&joint.axis) * dq[i];
            if let Some(ddq) = ddq {
                wd_i += joint.axis * ddq[i];
            }
            data.omega[i] = w_i;
            data.omega_dot[i] = wd_i;
            data.accel[i] = a_i;
            w = w_i;
            wd = wd_i;
            a = a_i;
        }
    }

    /// Classical acceleration of a frame's origin (world axes, linear then angular) after a
    /// [`Model::velocity_pass`] whose base acceleration was `base_accel`, with that offset removed.
    pub(crate) fn frame_acceleration_from_pass(
        &self,
        data: &Data,
        frame: FrameId,
        base_accel: Vector3<f64>,
    ) -> Vector6<f64> {
        let f = self.frame(frame);
        let Some(j) = f.joint else { return Vector6::zeros() };
        let r = f.placement.translation.vector;
        let (w, wd) = (data.omega[j], data.omega_dot[j]);
        let a_local = data.accel[j] + wd.cross(&r) + w.cross(&w.cross(&r));
        let rot = data.rotation[j];
        let lin = rot * a_local - base_accel;
        let ang = rot * wd;
        Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
    }

    /// J̇q̇ of a frame's origin, world axes (linear then angular): its classical acceleration at q̈ = 0,
    /// the term task-space control subtracts (p̈ = J q̈ + J̇q̇).
    pub fn frame_bias_acceleration(&self, data: &mut Data, q: &[f64], dq: &[f64], frame: FrameId) -> Vector6<f64> {
        self.check_len("dq", dq);
        self.forward_kinematics(data, q);
        self.velocity_pass(data, dq, None, Vector3::zeros());
        self.frame_acceleration_from_pass(data, frame, Vector3::zeros())
    }

    /// A frame's pose and twist at (q, q̇): one kinematics pass, reused by whatever is asked of `data`
    /// next at the same q.
    pub fn frame_motion(&self, data: &mut Data, q: &[f64], dq: &[f64], frame: FrameId) -> FrameMotion {
        let twist = self.frame_velocity(data, q, dq, frame);
        FrameMotion { pose: self.frame_pose(data, frame), twist }
    }

    /// Spatial velocity of a frame's origin (world axes, linear then angular), i.e. J q̇.
    pub fn frame_velocity(&self, data: &mut Data, q: &[f64], dq: &[f64], frame: FrameId) -> Vector6<f64> {
        self.check_len("dq", dq);
        self.forward_kinematics(data, q);
        let (_, p) = self.frame_rotation_position(data, frame);
        let (mut lin, mut ang) = (Vector3::zeros(), Vector3::zeros());
        if let Some(last) = self.frame(frame).joint {
            for (j, joint) in self.joints.iter().enumerate().take(last + 1) {
                let z = data.rotation[j] * joint.axis * dq[j];
                lin += z.cross(&(p - data.origin[j]));
                ang += z;
            }
        }
        Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
    }
}
