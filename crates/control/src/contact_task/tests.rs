//! The law alone, ticked on an arm standing still: commands refused and kept, the move across, the
//! sensor correction and the models it takes. (Whole-cell tests: nodes/tests/deformation_controller.rs.)

use nalgebra::{UnitQuaternion, Vector3};
use softcontact_contact::{ContactModel, Effect};

use super::across::{ACROSS_NORMAL_TOLERANCE, AcrossMove};
use super::*;
use crate::{LimitError, Quintic};

fn controller() -> DeformationController {
    DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), softcontact_sim::sponge()).unwrap()
}

/// `ticks` ticks of an arm standing at the start posture, no force.
fn tick(c: &mut DeformationController, ticks: usize) {
    for _ in 0..ticks {
        let time = c.last_tick.map_or(0.0, |t| t + c.config.period);
        c.tick(time, &softcontact_sim::DEFAULT_Q, &[0.0; 7], 0.0, &Vector3::zeros()).unwrap();
    }
}

#[test]
fn a_models_sensor_correction_is_taken_as_far_as_the_arms_torques_confirm_it() {
    let mut law = controller();
    let dt = 1e-3;
    // Reading 48 N, the model says the sensor reads 12 N low: the surface pushes 60 N if it is right.
    let mut settled = |arm: Option<f64>| {
        law.arm_smoothed = None;
        law.observe_arm_force(arm);
        law.sensor_correction(48.0, -12.0, dt)
    };
    assert_eq!(settled(Some(60.0)), -12.0, "the arm agrees with the corrected force");
    assert_eq!(settled(Some(48.0)), 0.0, "the arm agrees with the reading");
    assert_eq!(settled(Some(54.0)), 0.0, "half the correction away");
    assert!((settled(Some(57.0)) + 6.0).abs() < 1e-12, "a quarter away: half of it");
    assert_eq!(settled(None), 0.0, "no arm estimate: nothing confirmed");
    assert_eq!(settled(Some(f64::NAN)), 0.0, "a NaN confirms nothing");
    // At most MAX_SENSOR_CORRECTION of max_force, confirmed or not.
    law.arm_smoothed = None;
    law.observe_arm_force(Some(1048.0));
    let most = MAX_SENSOR_CORRECTION * law.config.limits.max_force;
    assert!(law.sensor_correction(48.0, -1000.0, dt).abs() <= most);
    // One tick of an arm that jumps moves the smoothed view by dt / ARM_FORCE_SMOOTHING of the jump.
    law.arm_smoothed = Some(48.0);
    law.observe_arm_force(Some(60.0));
    assert!(law.sensor_correction(48.0, -12.0, dt).abs() < 0.1);
}

#[test]
fn refused_across_commands_leave_the_plan_unchanged() {
    let mut c = controller();
    tick(&mut c, 10);
    c.command_across(Vector3::new(0.005, 0.005, 0.0), Vector3::new(0.0, 0.02, 0.0), 1.0).unwrap();
    tick(&mut c, 300);
    let before = (c.across, c.plan.clone(), c.across_reference());
    let unchanged = |c: &DeformationController, what: &str| {
        assert_eq!((c.across, c.plan.clone(), c.across_reference()), before, "{what} changed the plan");
    };
    let ok_lateral = Vector3::new(0.01, 0.0, 0.0);
    let ok_tilt = Vector3::new(0.05, 0.0, 0.0);
    for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300, f64::MAX] {
        for axis in 0..3 {
            let mut v = Vector3::zeros();
            v[axis] = x;
            let e = c.command_across(v, ok_tilt, 1.0).unwrap_err();
            assert!(x.is_finite() || matches!(e, ControlError::NonFinite(_)), "lateral {v:?}: {e}");
            unchanged(&c, &format!("a lateral offset of {x}"));
            let e = c.command_across(ok_lateral, v, 1.0).unwrap_err();
            assert!(x.is_finite() || matches!(e, ControlError::NonFinite(_)), "tilt {v:?}: {e}");
            unchanged(&c, &format!("a tilt of {x}"));
        }
    }
    for lateral in [Vector3::new(0.031, 0.0, 0.0), Vector3::new(0.0, -0.0301, 0.0), Vector3::new(0.022, 0.022, 0.0)] {
        let e = c.command_across(lateral, ok_tilt, 2.0).unwrap_err();
        assert!(matches!(e, ControlError::Across { limit: MAX_LATERAL, .. }), "lateral {lateral:?}: {e}");
        unchanged(&c, "an offset beyond MAX_LATERAL");
    }
    for tilt in [Vector3::new(0.36, 0.0, 0.0), Vector3::new(0.0, 0.0, -0.351), Vector3::new(0.25, 0.25, 0.0)] {
        let e = c.command_across(ok_lateral, tilt, 2.0).unwrap_err();
        assert!(matches!(e, ControlError::Across { limit: MAX_TILT, .. }), "tilt {tilt:?}: {e}");
        unchanged(&c, "a tilt beyond MAX_TILT");
    }
    for duration in [0.01, 0.099, 0.0, -1.0, 1e-300, 601.0, 1e300, f64::NAN, f64::INFINITY] {
        assert!(c.command_across(ok_lateral, ok_tilt, duration).is_err(), "duration {duration}");
        unchanged(&c, "a duration out of range");
    }
    assert!(matches!(c.command_across(ok_lateral, ok_tilt, 0.05), Err(ControlError::Limit(LimitError::Duration(..)))));
    // Too fast: 2.9 cm in 0.2 s peaks at 0.27 m/s (limit 0.25 m/s); 0.2 rad in 0.5 s at 0.75 rad/s.
    let e = c.command_across(Vector3::new(-0.028, 0.0, 0.0), ok_tilt, 0.2).unwrap_err();
    assert!(matches!(e, ControlError::Limit(LimitError::Rate(..))), "{e}");
    unchanged(&c, "a lateral move too fast");
    let e = c.command_across(ok_lateral, Vector3::new(0.0, 0.0, 0.2), 0.5).unwrap_err();
    assert!(matches!(e, ControlError::Across { limit: MAX_TILT_RATE, .. }), "{e}");
    unchanged(&c, "a tilt too fast");
    // The limits themselves are commands.
    c.command_across(Vector3::new(0.0, -MAX_LATERAL, 0.0), Vector3::new(0.0, 0.0, MAX_TILT), 2.0).unwrap();
}

#[test]
fn a_lateral_offset_along_the_normal_is_refused() {
    let mut c = controller();
    tick(&mut c, 10);
    for lateral in [Vector3::new(0.0, 0.0, 0.01), Vector3::new(0.0, 0.0, -0.01), Vector3::new(0.01, 0.0, 2e-6)] {
        let e = c.command_across(lateral, Vector3::zeros(), 1.0).unwrap_err();
        assert!(matches!(e, ControlError::Across { limit: ACROSS_NORMAL_TOLERANCE, .. }), "{lateral:?}: {e}");
        assert_eq!(c.across, None);
    }
    // Rounding along n is removed, not refused.
    c.command_across(Vector3::new(0.01, 0.0, 1e-9), Vector3::zeros(), 1.0).unwrap();
    tick(&mut c, 1100);
    assert_eq!(c.across_reference().lateral, Vector3::new(0.01, 0.0, 0.0));
}

#[test]
fn augmented_models_beyond_what_a_tared_sensor_or_a_resting_surface_has_are_refused() {
    let sponge = softcontact_sim::lab_sponge();
    let with = |effect: Effect| {
        let mut m = sponge.clone();
        m.effects.push(effect);
        m
    };
    let mut c = controller();
    let surface = Vector3::zeros();
    // Not finite, or beyond what a tared sensor or a surface at rest can have: refused, and the
    // model in use kept.
    for bad in [
        with(Effect::ViscoelasticRelaxation { stiffness: f64::NAN, time_constant: 0.1 }),
        with(Effect::ViscoelasticRelaxation { stiffness: 1e3, time_constant: f64::INFINITY }),
        with(Effect::ViscoelasticRelaxation { stiffness: -1e3, time_constant: 0.1 }),
        with(Effect::Hysteresis { fraction: 1.5, velocity_scale: 0.05 }),
        with(Effect::SensorBias { offset: 1e300 }),
        with(Effect::SensorBias { offset: -40.0 }),
        with(Effect::ContactOffsetDrift { rate: 0.01 }),
        with(Effect::SensorDrift { rate: 10.0 }),
        with(Effect::ViscoelasticRelaxation { stiffness: 1e300, time_constant: 0.15 }),
        ContactModel::new(softcontact_contact::Kind::KelvinVoigt, 1e300, 0.0).unwrap(),
        // Too soft to press: 6e-302 N at max_deformation.
        ContactModel::new(softcontact_contact::Kind::KelvinVoigt, 1e-300, 0.0).unwrap(),
        with(Effect::ViscoelasticRelaxation { stiffness: 1e3, time_constant: 1e-300 }),
        with(Effect::Hysteresis { fraction: 0.999999, velocity_scale: 0.05 }),
        with(Effect::Hysteresis { fraction: 0.5, velocity_scale: 1e-300 }),
        // Each within its bound, together beyond it.
        {
            let mut m = sponge.clone();
            m.effects = vec![Effect::ViscoelasticRelaxation { stiffness: 4e5, time_constant: 1e-3 }; 3];
            m
        },
        {
            let mut m = sponge.clone();
            m.effects = vec![Effect::Hysteresis { fraction: 0.3, velocity_scale: 0.05 }; 2];
            m
        },
        {
            let mut m = with(Effect::SensorBias { offset: 10.0 });
            m.effects.push(Effect::SensorBias { offset: 10.0 });
            m
        },
        {
            let mut m = with(Effect::ContactOffsetDrift { rate: 0.8e-3 });
            m.effects.push(Effect::ContactOffsetDrift { rate: 0.8e-3 });
            m
        },
        {
            let mut m = sponge.clone();
            m.effects = vec![Effect::ViscoelasticRelaxation { stiffness: 1e5, time_constant: 0.1 }; 1000];
            m
        },
        with(Effect::SensorDrift { rate: f64::NAN }),
        with(Effect::Adhesion { force: f64::NAN, range: 0.002 }),
        with(Effect::Adhesion { force: 1e300, range: 0.002 }),
        with(Effect::Adhesion { force: -5.0, range: 0.002 }),
        with(Effect::Adhesion { force: 5.0, range: f64::INFINITY }),
        with(Effect::Adhesion { force: 5.0, range: 1.0 }),
        with(Effect::Adhesion { force: 60.0, range: 0.002 }),
        with(Effect::QuasiLinearRelaxation { fraction: f64::NAN, time_constant: 0.5 }),
        with(Effect::QuasiLinearRelaxation { fraction: 1e300, time_constant: 0.5 }),
        with(Effect::QuasiLinearRelaxation { fraction: 0.2, time_constant: 1e-300 }),
        with(Effect::QuasiLinearRelaxation { fraction: -0.2, time_constant: 0.5 }),
        with(Effect::MediumDrag { damping: f64::NAN, tare_speed: 0.0 }),
        with(Effect::MediumDrag { damping: 1.0, tare_speed: f64::INFINITY }),
        with(Effect::MediumDrag { damping: 1e300, tare_speed: 0.0 }),
        with(Effect::MediumDrag { damping: -1.0, tare_speed: 0.0 }),
        with(Effect::MediumDrag { damping: 1.0, tare_speed: 2.0 }),
        with(Effect::MediumDrag { damping: 150.0, tare_speed: 0.0 }),
        with(Effect::SqueezeFilm { damping: f64::NAN, reach: 1e-3 }),
        with(Effect::SqueezeFilm { damping: 1.0, reach: f64::INFINITY }),
        with(Effect::SqueezeFilm { damping: 1e300, reach: 1e-3 }),
        with(Effect::SqueezeFilm { damping: -1.0, reach: 1e-3 }),
        with(Effect::SqueezeFilm { damping: 1.0, reach: 0.0 }),
        with(Effect::SqueezeFilm { damping: 1.0, reach: 1.0 }),
        with(Effect::SqueezeFilm { damping: 150.0, reach: 1e-3 }),
    ] {
        assert!(c.adopt_estimate(bad.clone(), &surface, None).is_err(), "{bad:?}");
        assert_eq!(c.contact_model(), &softcontact_sim::sponge());
        // As the initial model (a node's start-up): refused too.
        assert!(DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), bad.clone()).is_err(), "{bad:?}");
    }
}

#[test]
fn a_new_command_mid_move_starts_from_the_present_reference() {
    let mut c = controller();
    tick(&mut c, 10);
    c.command_across(Vector3::new(0.01, 0.0, 0.0), Vector3::new(0.0, 0.05, 0.0), 1.0).unwrap();
    tick(&mut c, 400);
    let now = c.across_reference();
    c.command_across(Vector3::new(0.0, 0.01, 0.0), Vector3::new(0.05, 0.0, 0.0), 1.0).unwrap();
    let from = c.across_reference();
    assert!((from.lateral - now.lateral).norm() < 1e-15 && (from.tilt - now.tilt).norm() < 1e-15);
    assert!(now.lateral.x > 0.001 && now.lateral.x < 0.009, "mid-move: {now:?}");
    tick(&mut c, 1000);
    let end = c.across_reference();
    assert!(end.velocity.norm() < 1e-12 && end.angular_velocity.norm() < 1e-12, "{end:?}");
    assert!((end.lateral - Vector3::new(0.0, 0.01, 0.0)).norm() < 1e-12);
    assert!((end.tilt - Vector3::new(0.05, 0.0, 0.0)).norm() < 1e-12);
}

#[test]
fn a_failed_tick_stops_the_move_across_where_its_reference_is() {
    let mut c = controller();
    tick(&mut c, 10);
    c.command_across(Vector3::new(0.01, 0.0, 0.0), Vector3::new(0.0, 0.05, 0.0), 1.0).unwrap();
    tick(&mut c, 400);
    let now = c.across_reference();
    c.hold_across();
    tick(&mut c, 1000);
    let held = c.across_reference();
    assert!((held.lateral - now.lateral).norm() < 1e-15 && (held.tilt - now.tilt).norm() < 1e-15);
    assert_eq!((held.velocity, held.angular_velocity), (Vector3::zeros(), Vector3::zeros()));
}

#[test]
fn restarts_and_new_sessions_hold_the_start_again() {
    let mut c = controller();
    let moving = |c: &mut DeformationController| {
        c.follow_session(Some(2), true, 0.0);
        tick(c, 10);
        c.command_across(Vector3::new(0.01, 0.0, 0.0), Vector3::new(0.0, 0.05, 0.0), 1.0).unwrap();
        tick(c, 500);
        assert!(c.across.is_some() && c.across_reference().lateral.x > 0.004);
    };
    moving(&mut c);
    c.restart();
    assert_eq!((c.across, c.across_reference()), (None, AcrossReference::HOLD_START));
    // A new KRC session, joint states after a silence, a KRC that stopped commanding.
    for (session, commanding, silence) in
        [(Some(3), true, 0.0), (None, true, 0.0), (Some(2), true, 1.0), (Some(2), false, 0.0)]
    {
        moving(&mut c);
        c.follow_session(session, commanding, silence);
        assert_eq!(c.across, None, "session {session:?}, commanding {commanding}, silence {silence} s");
        assert_eq!(c.across_reference(), AcrossReference::HOLD_START);
    }
    // The same session, commanding, on time: the move goes on.
    moving(&mut c);
    c.follow_session(Some(2), true, 0.001);
    assert!(c.across.is_some());
}

#[test]
fn the_reference_angular_velocity_is_that_of_the_reference_rotation() {
    let progress = Quintic::rest_to_rest(0.0, 1.0, 1.0).unwrap();
    let m = AcrossMove {
        from: (Vector3::zeros(), Vector3::new(0.15, -0.05, 0.0)),
        to: (Vector3::zeros(), Vector3::new(-0.05, 0.1, 0.12)),
        progress,
        since: 0.0,
    };
    let h = 1e-6;
    // The quintic's peak acceleration: 10/√3 per unit distance and s².
    let peak_alpha = 10.0 / 3f64.sqrt() * (m.to.1 - m.from.1).norm();
    for t in [0.1, 0.3, 0.5, 0.8] {
        let rotation = |t: f64| UnitQuaternion::from_scaled_axis(m.at(t).tilt);
        // World angular velocity: Ṙ Rᵀ.
        let numeric = (rotation(t + h) * rotation(t - h).inverse()).scaled_axis() / (2.0 * h);
        let w = m.at(t).angular_velocity;
        assert!((numeric - w).norm() < 1e-6 * w.norm().max(1.0), "t {t}: {numeric:?} vs {w:?}");
        let alpha = (m.at(t + h).angular_velocity - m.at(t - h).angular_velocity) / (2.0 * h);
        let fed = m.at(t).angular_acceleration;
        // Without J̇_l·θ̇: within 1 % of the peak.
        assert!((alpha - fed).norm() < 0.01 * peak_alpha, "t {t}: {alpha:?} vs {fed:?}");
    }
}
