//! The control laws against their definitions: quintic boundary conditions, the deformation law in
//! closed loop, and eq. 15 checked in the arm's own forward dynamics.

use nalgebra::{DVector, Vector3, Vector6};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use softcontact_contact::{ContactModel, Kind};
use softcontact_control::{
    Damping, DeformationGains, Oscillation, Quintic, Reference, Segment, SetpointSequence, Trajectory,
    deformation_acceleration, force_to_deformation, task_space_torque,
};
use softcontact_dynamics::{ExternalWrench, lwr4};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

#[test]
fn quintics_meet_their_boundary_conditions_exactly() {
    let mut rng = SmallRng::seed_from_u64(1);
    for _ in 0..1000 {
        let mut state = || Reference {
            position: rng.random_range(-1.0..1.0),
            velocity: rng.random_range(-2.0..2.0),
            acceleration: rng.random_range(-5.0..5.0),
        };
        let (s, e) = (state(), state());
        let t = rng.random_range(0.1..5.0);
        let q = Quintic::new(s, e, t).unwrap();
        for (got, want) in [(q.at(0.0), s), (q.at(t), e)] {
            assert!(close(got.position, want.position, 1e-9), "{got:?} vs {want:?}");
            assert!(close(got.velocity, want.velocity, 1e-9), "{got:?} vs {want:?}");
            assert!(close(got.acceleration, want.acceleration, 1e-8), "{got:?} vs {want:?}");
        }
        // Velocity and acceleration are the derivatives of position (central differences).
        let (tm, h) = (0.37 * t, 1e-5);
        let d = |f: &dyn Fn(f64) -> f64| (f(tm + h) - f(tm - h)) / (2.0 * h);
        assert!(close(d(&|x| q.at(x).position), q.at(tm).velocity, 1e-6));
        assert!(close(d(&|x| q.at(x).velocity), q.at(tm).acceleration, 1e-6));
    }
    assert!(Quintic::rest_to_rest(0.0, 1.0, 0.0).is_none());
    assert!(Quintic::rest_to_rest(f64::NAN, 1.0, 2.0).is_none());
    // Durations whose powers overflow give no quintic at all (they gave NaN coefficients).
    for huge in [1e154, 1e200, f64::MAX] {
        assert!(Quintic::rest_to_rest(0.0, 0.01, huge).is_none(), "{huge}");
    }
    assert!(Quintic::rest_to_rest(0.0, 0.01, 1e-300).is_none());
}

#[test]
fn a_setpoint_sequence_moves_two_seconds_each_and_joins_smoothly() {
    let seq = SetpointSequence::new(0.0, &[0.02, 0.01, 0.03], 2.0).unwrap();
    assert_eq!(seq.duration(), 6.0);
    for (t, want) in [(0.0, 0.0), (2.0, 0.02), (4.0, 0.01), (6.0, 0.03), (7.0, 0.03)] {
        let (r, _) = seq.at(t);
        assert!((r.position - want).abs() < 1e-12 && r.velocity.abs() < 1e-12, "t = {t}: {r:?}");
    }
    let (before, i) = seq.at(2.0 - 1e-9);
    let (after, j) = seq.at(2.0 + 1e-9);
    assert_eq!((i, j), (0, 1));
    assert!((before.position - after.position).abs() < 1e-9 && (before.acceleration - after.acceleration).abs() < 1e-6);
}

#[test]
fn pushes_joined_by_quintics_are_smooth_in_position_velocity_and_acceleration() {
    // The force-control paper's identification: a ramp into the sine's lowest point, 3 periods at 1 Hz, a retreat.
    let push = Oscillation { mean: 0.03, amplitude: 0.02, frequency: 1.0, periods: 3 };
    let ramp = Quintic::new(Reference::default(), push.start(), 1.0).unwrap();
    let retreat = Quintic::new(push.start(), Reference { position: -0.02, ..Default::default() }, 1.0).unwrap();
    let mut plan =
        Trajectory::new(vec![Segment::Move(ramp), Segment::Oscillate(push), Segment::Move(retreat)]).unwrap();
    assert!(close(plan.duration(), 5.0, 1e-12));
    // The sine analytically: lowest at whole periods, highest half-way, ẋ and ẍ its derivatives.
    assert!(close(plan.at(1.0).position, 0.01, 1e-12) && close(plan.at(1.5).position, 0.05, 1e-12));
    assert!(close(plan.at(1.25).velocity, 0.02 * std::f64::consts::TAU, 1e-12));
    // Derivatives are the finite differences of the level below, across both junctions.
    let h = 1e-6;
    for k in 1..5000 {
        let t = k as f64 * 1e-3;
        let (a, b) = (plan.at(t - h), plan.at(t + h));
        let r = plan.at(t);
        assert!(close((b.position - a.position) / (2.0 * h), r.velocity, 1e-6), "velocity at {t}");
        assert!(close((b.velocity - a.velocity) / (2.0 * h), r.acceleration, 1e-4), "acceleration at {t}");
    }
    // Past the end it holds the retreat point; an offset moves every position and nothing else.
    let end = plan.at(9.0);
    assert!(close(end.position, -0.02, 1e-12) && end.velocity.abs() < 1e-12 && end.acceleration == 0.0);
    let before = plan.at(2.3);
    plan.offset = 0.004;
    let after = plan.at(2.3);
    assert!(close(after.position - before.position, 0.004, 1e-15) && after.velocity == before.velocity);
    assert!(Trajectory::new(vec![]).is_none());
}

#[test]
fn the_deformation_law_tracks_its_reference() {
    let gains = DeformationGains::critically_damped(20.0);
    let r = Reference { position: 0.02, velocity: 0.1, acceleration: 0.5 };
    let a = deformation_acceleration(&gains, &r, 0.015, 0.12);
    assert!((a - (0.5 + 400.0 * 0.005 + 40.0 * (-0.02))).abs() < 1e-12);
    // Closed loop on a double integrator, starting 5 mm off: the error decays to nothing.
    let sponge = ContactModel::new(Kind::AzadFeatherstone, 25_044.0, 1100.0).unwrap();
    let target = force_to_deformation(&sponge, 140.0).unwrap();
    let move_ = Quintic::rest_to_rest(0.0, target, 2.0).unwrap();
    let (mut z, mut zd, dt) = (0.005, 0.0, 1e-4);
    for k in 0..30_000 {
        let zdd = deformation_acceleration(&gains, &move_.at(k as f64 * dt), z, zd);
        zd += zdd * dt;
        z += zd * dt;
    }
    assert!((z - target).abs() < 1e-6, "z {z} vs {target}");
    assert!((sponge.force(z, 0.0).unwrap() - 140.0).abs() < 0.02);
}

/// States of the LWR away from singularities, with the hand on a surface pushing back.
fn scenarios() -> Vec<([f64; 7], [f64; 7], Vector6<f64>)> {
    let mut rng = SmallRng::seed_from_u64(2);
    (0..100)
        .map(|_| {
            let q = [
                rng.random_range(-1.0..1.0),
                rng.random_range(0.3..1.2),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.8..-0.5),
                rng.random_range(-1.0..1.0),
                rng.random_range(0.4..1.5),
                rng.random_range(-1.0..1.0),
            ];
            let dq = std::array::from_fn(|_| rng.random_range(-0.5..0.5));
            let f = Vector6::new(
                rng.random_range(-5.0..5.0),
                rng.random_range(-5.0..5.0),
                rng.random_range(0.0..200.0),
                0.1,
                -0.2,
                0.05,
            );
            (q, dq, f)
        })
        .collect()
}

#[test]
fn the_commanded_task_acceleration_is_what_the_arm_does() {
    let model = lwr4::model();
    let mut data = model.data();
    let mut plant = model.data();
    let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
    let mut rng = SmallRng::seed_from_u64(3);
    for (q, dq, f) in scenarios() {
        let want = Vector6::from_fn(|_, _| rng.random_range(-2.0..2.0));
        let tau0 = DVector::from_fn(7, |_, _| rng.random_range(-5.0..5.0));
        let terms = model.control_terms(&mut data, &q, &dq, tool).unwrap();
        let out = task_space_torque(&terms, &want, &f, &tau0, &Damping::default());
        assert!(!out.damped);
        // The plant: the same arm with the contact wrench acting on the hand.
        let w = ExternalWrench {
            frame: tool,
            force: Vector3::new(f[0], f[1], f[2]),
            torque: Vector3::new(f[3], f[4], f[5]),
        };
        let ddq = model.forward_dynamics(&mut plant, &q, &dq, out.tau.as_slice(), Some(&w)).unwrap().clone();
        let bias = model.frame_bias_acceleration(&mut plant, &q, &dq, tool);
        model.forward_kinematics(&mut plant, &q);
        let mut j = nalgebra::Matrix6xX::zeros(7);
        model.frame_jacobian(&plant, tool, softcontact_dynamics::Axes::World, &mut j);
        let got = j * ddq + bias;
        assert!((got - want).amax() < 1e-9 * want.amax().max(1.0), "achieved {got} vs commanded {want}");
    }
}

#[test]
fn null_space_torques_cause_no_task_acceleration() {
    let model = lwr4::model();
    let mut data = model.data();
    let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
    let mut rng = SmallRng::seed_from_u64(4);
    for (q, dq, f) in scenarios() {
        let terms = model.control_terms(&mut data, &q, &dq, tool).unwrap();
        let tau0 = DVector::from_fn(7, |_, _| rng.random_range(-20.0..20.0));
        let out = task_space_torque(&terms, &Vector6::zeros(), &f, &tau0, &Damping::default());
        let a = terms.jacobian * terms.mass_matrix_inverse;
        let leak = &a * (&out.projector * &tau0);
        assert!(leak.amax() < 1e-9 * (&a * &tau0).amax().max(1.0), "J M⁻¹ N τ₀ = {leak}");
        assert!((&out.tau - &out.task - &out.projector * &tau0).amax() < 1e-9);
    }
}

#[test]
fn near_a_singularity_the_inversion_is_damped_and_torques_stay_bounded() {
    let model = lwr4::model();
    let mut data = model.data();
    let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
    // The candle: the arm stretched straight up is singular.
    let q = [0.0; 7];
    let terms = model.control_terms(&mut data, &q, &[0.0; 7], tool).unwrap();
    let out = task_space_torque(
        &terms,
        &Vector6::new(0.0, 0.0, -1.0, 0.0, 0.0, 0.0),
        &Vector6::zeros(),
        &DVector::zeros(7),
        &Damping::default(),
    );
    assert!(out.damped);
    assert!(out.tau.iter().all(|t| t.is_finite()) && out.tau.amax() < 1e3, "{}", out.tau);
}

#[test]
fn limits_refuse_bad_commands_and_bound_torques() {
    use softcontact_control::{LimitError, Limits, TorqueLimiter};
    let limits = Limits {
        joint_torque: vec![176.0, 176.0, 100.0, 100.0, 100.0, 38.0, 38.0],
        torque_rate: 1000.0,
        max_force: 250.0,
        max_deformation: 0.06,
        max_lift: 0.05,
        move_duration: (0.1, 600.0),
        max_deformation_rate: 0.1,
        contact_lost_below: 0.5,
        force_limit: 1.2 * 250.0,
    };
    assert_eq!(limits.check_force(100.0), Ok(100.0));
    assert_eq!(limits.check_force(300.0), Err(LimitError::Force(300.0, 250.0)));
    assert_eq!(limits.check_force(-1.0), Err(LimitError::Force(-1.0, 250.0)));
    assert_eq!(limits.check_force(f64::NAN), Err(LimitError::NonFinite("the force command")));
    assert!(limits.check_deformation(0.07).is_err());
    assert_eq!(limits.check_deformation(-0.06), Err(LimitError::Lift(0.06, 0.05)));
    assert_eq!(limits.check_deformation(-1e300), Err(LimitError::Lift(1e300, 0.05)));
    assert_eq!(limits.check_duration(2.0), Ok(2.0));
    for bad in [0.0, 0.05, -1.0, 601.0, 1e200] {
        assert_eq!(limits.check_duration(bad), Err(LimitError::Duration(bad, 0.1, 600.0)));
    }
    assert_eq!(limits.check_duration(f64::INFINITY), Err(LimitError::NonFinite("the move duration")));
    assert_eq!(limits.check_deformation(f64::NAN), Err(LimitError::NonFinite("the deformation command")));
    assert_eq!(limits.check_rate(f64::NEG_INFINITY), Err(LimitError::NonFinite("the move's speed")));
    assert_eq!(LimitError::NonFinite("the move duration").to_string(), "the move duration is not a finite number");
    assert_eq!(limits.check_rate(-0.05), Ok(-0.05));
    assert_eq!(limits.check_rate(0.2), Err(LimitError::Rate(0.2, 0.1)));
    // A rest-to-rest quintic peaks at 15/8 of the mean speed, at mid-move.
    let q = softcontact_control::Quintic::rest_to_rest(0.0, 0.02, 2.0).unwrap();
    assert!((q.peak_velocity() - 15.0 / 8.0 * 0.01).abs() < 1e-12);
    let mut limiter = TorqueLimiter::new();
    let mut tau = vec![0.0; 7];
    limiter.apply(&limits, &mut tau, 1e-3).unwrap();
    // A step of 50 N·m is spread over ticks at 1000 N·m/s: 1 N·m per 1 ms tick.
    let mut step = vec![50.0, -50.0, 0.0, 0.0, 0.0, 200.0, 0.0];
    limiter.apply(&limits, &mut step, 1e-3).unwrap();
    assert_eq!(step, vec![1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    // A non-finite torque is refused whole, never replaced by the last one.
    let mut bad = vec![1.0, 1.0, 1.0, 1.0, 1.0, 1.0, f64::NAN];
    assert_eq!(limiter.apply(&limits, &mut bad, 1e-3), Err(LimitError::NonFiniteTorque(6)));
    let mut inf = vec![f64::INFINITY; 7];
    assert_eq!(limiter.apply(&limits, &mut inf, 1e-3), Err(LimitError::NonFiniteTorque(0)));
    for _ in 0..100 {
        let mut big = vec![500.0; 7];
        limiter.apply(&limits, &mut big, 1e-3).unwrap();
        assert!(big.iter().zip(&limits.joint_torque).all(|(t, l)| t.abs() <= *l));
    }
    assert!(limiter.clipped >= 100);
}
