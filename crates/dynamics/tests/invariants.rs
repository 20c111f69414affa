//! Physical and mathematical invariants of the dynamics, independent of any reference implementation.

use std::path::PathBuf;

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6xX, Vector3};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use softcontact_dynamics::{Axes, ExternalWrench, Model};

fn urdf_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../urdf/lwr4.urdf")
}

fn model() -> Model {
    Model::from_urdf_file(urdf_path()).unwrap()
}

fn random_state(model: &Model, rng: &mut SmallRng) -> (Vec<f64>, Vec<f64>) {
    let q = model.joints.iter().map(|j| rng.random_range(j.limits.lower..j.limits.upper)).collect();
    let dq = (0..model.dof()).map(|_| rng.random_range(-2.0..2.0)).collect();
    (q, dq)
}

#[test]
fn mass_matrix_is_symmetric_positive_definite() {
    let model = model();
    let mut data = model.data();
    let mut rng = SmallRng::seed_from_u64(1);
    for _ in 0..500 {
        let (q, _) = random_state(&model, &mut rng);
        let m = model.mass_matrix(&mut data, &q).clone();
        assert!((&m - m.transpose()).amax() == 0.0, "M not symmetric");
        let eig = m.symmetric_eigenvalues();
        assert!(eig.min() > 1e-4, "M not positive definite: eigenvalues {eig}");
    }
}

/// Rotation vector of a small rotation R, from its skew part (exact to O(θ³); acos-based logs lose
/// half the digits near the identity).
fn log_small(r: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(r[(2, 1)] - r[(1, 2)], r[(0, 2)] - r[(2, 0)], r[(1, 0)] - r[(0, 1)]) / 2.0
}

#[test]
fn jacobian_is_the_derivative_of_forward_kinematics() {
    let model = model();
    let mut data = model.data();
    let mut rng = SmallRng::seed_from_u64(2);
    let eps = 1e-6;
    let mut jac = Matrix6xX::zeros(model.dof());
    for name in ["lwr_link_3", "lwr_flange", "ft_sensor", "lwr_tool"] {
        let frame = model.frame_id(name).unwrap();
        for _ in 0..50 {
            let (q, _) = random_state(&model, &mut rng);
            model.forward_kinematics(&mut data, &q);
            model.frame_jacobian(&data, frame, Axes::World, &mut jac);
            for i in 0..model.dof() {
                let mut qp = q.clone();
                let mut qm = q.clone();
                qp[i] += eps;
                qm[i] -= eps;
                model.forward_kinematics(&mut data, &qp);
                let plus = model.frame_pose(&data, frame);
                model.forward_kinematics(&mut data, &qm);
                let minus = model.frame_pose(&data, frame);
                let dp = (plus.translation.vector - minus.translation.vector) / (2.0 * eps);
                let rp = plus.rotation.to_rotation_matrix().into_inner();
                let rm = minus.rotation.to_rotation_matrix().into_inner();
                let dw = log_small(&(rp * rm.transpose())) / (2.0 * eps);
                for r in 0..3 {
                    assert!((jac[(r, i)] - dp[r]).abs() < 1e-8, "{name}: linear row {r} col {i}");
                    assert!((jac[(r + 3, i)] - dw[r]).abs() < 1e-8, "{name}: angular row {r} col {i}");
                }
            }
        }
    }
}

#[test]
fn bias_acceleration_is_the_time_derivative_of_the_jacobian_along_the_motion() {
    let model = model();
    let mut data = model.data();
    let mut rng = SmallRng::seed_from_u64(3);
    let tool = model.frame_id("lwr_tool").unwrap();
    let eps = 1e-6;
    let (mut jp, mut jm) = (Matrix6xX::zeros(model.dof()), Matrix6xX::zeros(model.dof()));
    for _ in 0..100 {
        let (q, dq) = random_state(&model, &mut rng);
        let qp: Vec<f64> = q.iter().zip(&dq).map(|(a, b)| a + eps * b).collect();
        let qm: Vec<f64> = q.iter().zip(&dq).map(|(a, b)| a - eps * b).collect();
        model.forward_kinematics(&mut data, &qp);
        model.frame_jacobian(&data, tool, Axes::World, &mut jp);
        model.forward_kinematics(&mut data, &qm);
        model.frame_jacobian(&data, tool, Axes::World, &mut jm);
        let fd = (&jp - &jm) / (2.0 * eps) * DVector::from_column_slice(&dq);
        let ours = model.frame_bias_acceleration(&mut data, &q, &dq, tool);
        assert!((ours - fd).amax() < 1e-6, "J̇q̇ {ours} vs finite differences {fd}");
    }
}

#[test]
fn inverse_dynamics_inverts_forward_dynamics() {
    let model = model();
    let mut data = model.data();
    let mut rng = SmallRng::seed_from_u64(4);
    let tool = model.frame_id("lwr_tool").unwrap();
    for _ in 0..500 {
        let (q, dq) = random_state(&model, &mut rng);
        let tau: Vec<f64> = (0..model.dof()).map(|_| rng.random_range(-50.0..50.0)).collect();
        let w = ExternalWrench {
            frame: tool,
            force: Vector3::new(
                rng.random_range(-50.0..50.0),
                rng.random_range(-50.0..50.0),
                rng.random_range(-50.0..50.0),
            ),
            torque: Vector3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0)),
        };
        for external in [None, Some(&w)] {
            let ddq = model.forward_dynamics(&mut data, &q, &dq, &tau, external).unwrap().as_slice().to_vec();
            let back = model.rnea(&mut data, &q, &dq, &ddq, external);
            let err = (back - DVector::from_column_slice(&tau)).amax();
            assert!(err < 1e-9 * 50.0, "RNEA(FD(τ)) − τ = {err:e}");
        }
    }
}

#[test]
fn external_wrench_enters_as_jacobian_transpose() {
    let model = model();
    let mut data = model.data();
    let mut rng = SmallRng::seed_from_u64(5);
    let tool = model.frame_id("lwr_tool").unwrap();
    let mut jac = Matrix6xX::zeros(model.dof());
    for _ in 0..100 {
        let (q, dq) = random_state(&model, &mut rng);
        let ddq = vec![0.3; model.dof()];
        let w =
            ExternalWrench { frame: tool, force: Vector3::new(3.0, -20.0, 40.0), torque: Vector3::new(0.5, 1.0, -2.0) };
        let free = model.rnea(&mut data, &q, &dq, &ddq, None).clone();
        let pushed = model.rnea(&mut data, &q, &dq, &ddq, Some(&w)).clone();
        model.forward_kinematics(&mut data, &q);
        model.frame_jacobian(&data, tool, Axes::World, &mut jac);
        let wrench = nalgebra::Vector6::new(3.0, -20.0, 40.0, 0.5, 1.0, -2.0);
        let expected = free - jac.transpose() * wrench;
        assert!((pushed - expected).amax() < 1e-10);
    }
}

/// Zero torque, RK4 with a fine step: total energy is conserved.
#[test]
fn free_swing_conserves_energy() {
    let model = model();
    let mut data = model.data();
    let n = model.dof();
    let zero = vec![0.0; n];
    let mut q = vec![0.3, 1.2, -0.4, -1.0, 0.5, 0.8, 0.2];
    let mut dq = vec![0.0; n];
    let energy = |data: &mut softcontact_dynamics::Data, q: &[f64], dq: &[f64]| {
        model.kinetic_energy(data, q, dq) + model.potential_energy(data, q)
    };
    let e0 = energy(&mut data, &q, &dq);
    let (h, steps) = (2e-4, 50_000); // 10 s
    let mut max_kinetic: f64 = 0.0;
    let mut max_drift: f64 = 0.0;
    let fd = |data: &mut softcontact_dynamics::Data, q: &[f64], dq: &[f64]| -> Vec<f64> {
        model.forward_dynamics(data, q, dq, &zero, None).unwrap().as_slice().to_vec()
    };
    for _ in 0..steps {
        let add = |a: &[f64], b: &[f64], s: f64| -> Vec<f64> { a.iter().zip(b).map(|(x, y)| x + s * y).collect() };
        let k1v = fd(&mut data, &q, &dq);
        let k1q = dq.clone();
        let (q2, v2) = (add(&q, &k1q, h / 2.0), add(&dq, &k1v, h / 2.0));
        let k2v = fd(&mut data, &q2, &v2);
        let k2q = v2;
        let (q3, v3) = (add(&q, &k2q, h / 2.0), add(&dq, &k2v, h / 2.0));
        let k3v = fd(&mut data, &q3, &v3);
        let k3q = v3;
        let (q4, v4) = (add(&q, &k3q, h), add(&dq, &k3v, h));
        let k4v = fd(&mut data, &q4, &v4);
        let k4q = v4;
        for i in 0..n {
            q[i] += h / 6.0 * (k1q[i] + 2.0 * k2q[i] + 2.0 * k3q[i] + k4q[i]);
            dq[i] += h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
        }
        max_kinetic = max_kinetic.max(model.kinetic_energy(&mut data, &q, &dq));
        max_drift = max_drift.max((energy(&mut data, &q, &dq) - e0).abs());
    }
    // Relative to the energy that changed form during the swing (the potential's zero is arbitrary).
    assert!(max_kinetic > 10.0, "the arm should swing: max kinetic energy {max_kinetic} J");
    let relative = max_drift / max_kinetic;
    eprintln!(
        "free swing, 10 s, RK4 at 0.2 ms: energy drift {max_drift:e} J, {relative:e} of the largest kinetic energy {max_kinetic:.2} J"
    );
    assert!(relative < 1e-6, "energy drift {max_drift:e} J over max kinetic {max_kinetic} J = {relative:e}");
}

/// With a torque, the rate of change of energy is the power q̇ᵀτ.
#[test]
fn energy_rate_is_the_input_power() {
    let model = model();
    let mut data = model.data();
    let mut rng = SmallRng::seed_from_u64(6);
    for _ in 0..100 {
        let (q, dq) = random_state(&model, &mut rng);
        let tau: Vec<f64> = (0..model.dof()).map(|_| rng.random_range(-20.0..20.0)).collect();
        let ddq = model.forward_dynamics(&mut data, &q, &dq, &tau, None).unwrap().as_slice().to_vec();
        let eps = 1e-6;
        let at = |s: f64, data: &mut softcontact_dynamics::Data| {
            let qs: Vec<f64> = (0..7).map(|i| q[i] + s * dq[i] + 0.5 * s * s * ddq[i]).collect();
            let vs: Vec<f64> = (0..7).map(|i| dq[i] + s * ddq[i]).collect();
            model.kinetic_energy(data, &qs, &vs) + model.potential_energy(data, &qs)
        };
        let rate = (at(eps, &mut data) - at(-eps, &mut data)) / (2.0 * eps);
        let power: f64 = dq.iter().zip(&tau).map(|(a, b)| a * b).sum();
        assert!((rate - power).abs() < 1e-5 * power.abs().max(1.0), "dE/dt {rate} vs q̇ᵀτ {power}");
    }
}

/// Gravity torques of the bare arm (no sensor, no hand) against the table computed for the robot-model
/// notes (Set A, g = 9.81), given to 0.1 N·m.
#[test]
fn bare_arm_gravity_matches_the_published_table() {
    let mut robot = urdf_rs::read_file(urdf_path()).unwrap();
    let flange_subtree = ["ft_sensor_body", "ft_sensor", "lwr_hand", "lwr_tool"];
    robot.links.retain(|l| !flange_subtree.contains(&l.name.as_str()));
    robot.joints.retain(|j| !flange_subtree.contains(&j.child.link.as_str()));
    let model = Model::from_urdf(&robot).unwrap();
    let mut data = model.data();
    let d = std::f64::consts::PI / 180.0;
    let cases: [([f64; 7], [f64; 7]); 2] = [
        ([0.0, 90.0 * d, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, -42.4, -0.5, 12.2, -0.3, 0.0, 0.0]),
        ([0.0, 45.0 * d, 0.0, -90.0 * d, 0.0, 45.0 * d, 0.0], [0.0, -30.0, -0.3, 8.6, -0.2, 0.0, 0.0]),
    ];
    for (q, expected) in cases {
        let g = model.gravity_torques(&mut data, &q);
        for i in 0..7 {
            assert!((g[i] - expected[i]).abs() <= 0.051, "joint {i}: {} vs table {}", g[i], expected[i]);
        }
    }
    assert!((model.moving_mass() - 12.4158).abs() < 1e-3, "moving mass {}", model.moving_mass());
}

#[test]
fn control_terms_agree_with_the_separate_algorithms() {
    let model = model();
    let mut data = model.data();
    let mut other = model.data();
    let mut rng = SmallRng::seed_from_u64(7);
    let tool = model.frame_id("lwr_tool").unwrap();
    for _ in 0..50 {
        let (q, dq) = random_state(&model, &mut rng);
        let t = model.control_terms(&mut data, &q, &dq, tool).unwrap();
        let m: DMatrix<f64> = t.mass_matrix.clone();
        assert!((t.mass_matrix_inverse * &m - DMatrix::identity(7, 7)).amax() < 1e-10);
        assert!((m - model.mass_matrix(&mut other, &q)).amax() == 0.0);
        let h = t.nonlinear_effects.clone();
        assert!((h - model.nonlinear_effects(&mut other, &q, &dq)).amax() < 1e-12);
    }
}

/// A point mass carried at the tool frame changes the gravity torques by m Jᵀ(0, 0, g) — the Jacobian of
/// that frame's origin, world axes — and M by m JᵀJ; a frame fixed to the world carries nothing.
#[test]
fn a_payload_adds_its_weight_and_inertia_through_its_frames_jacobian() {
    use softcontact_dynamics::BodyInertia;
    let model = model();
    let tool = model.frame_id(softcontact_dynamics::lwr4::TOOL_FRAME).unwrap();
    let mass = 0.7;
    let heavier = model.with_payload(tool, &BodyInertia::from_com(mass, Vector3::zeros(), Matrix3::zeros())).unwrap();
    let (mut data, mut heavy_data) = (model.data(), heavier.data());
    let mut rng = SmallRng::seed_from_u64(11);
    for _ in 0..20 {
        let (q, _) = random_state(&model, &mut rng);
        model.forward_kinematics(&mut data, &q);
        let mut j = Matrix6xX::zeros(7);
        model.frame_jacobian(&data, tool, Axes::World, &mut j);
        let lin = j.rows(0, 3).into_owned();
        let expected = mass * lin.transpose() * Vector3::new(0.0, 0.0, 9.81);
        let dg = heavier.gravity_torques(&mut heavy_data, &q) - model.gravity_torques(&mut data, &q);
        assert!((&dg - &expected).amax() < 1e-9, "Δg {dg} vs {expected}");
        let dm = heavier.mass_matrix(&mut heavy_data, &q) - model.mass_matrix(&mut data, &q);
        assert!((&dm - mass * lin.transpose() * &lin).amax() < 1e-9);
    }
    let world = model.frames.iter().position(|f| f.joint.is_none()).unwrap();
    assert!(model.with_payload(softcontact_dynamics::FrameId(world), &BodyInertia::ZERO).is_err());
}
