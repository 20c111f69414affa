//! The contact model type: forces against hand-written laws, derivatives against finite differences,
//! the inverse, YAML, the tangential law and the effects.

mod common;

use proptest::prelude::*;
use softcontact_contact::{
    ContactError, ContactModel, DELAY_LINE, Effect, Exponents, Kind, SensorInputs, Tangential, gravity_change,
};

#[test]
fn forces_match_the_laws_of_the_paper() {
    for kind in Kind::CANDIDATES {
        let model = ContactModel::new(kind, 2.5e4, 700.0).unwrap();
        for (z, zd) in [(0.01, 0.1), (0.03, -0.05), (0.05, 0.0), (-0.01, 0.3), (0.0, 1.0), (0.02, -3.0)] {
            let ours = model.force(z, zd).unwrap();
            let law = common::closed_form(kind, 2.5e4, 700.0, z, zd);
            assert!((ours - law).abs() <= 1e-12 * law.abs().max(1.0), "{kind:?} at ({z}, {zd}): {ours} vs {law}");
        }
    }
    let general = ContactModel::general(100.0, 3.0, Exponents { a: 1.3, b: 0.7, c: 0.8 }).unwrap();
    let (z, zd): (f64, f64) = (0.04, -0.2);
    let law = 100.0 * z.powf(1.3) - 3.0 * z.powf(0.7) * 0.2f64.powf(0.8);
    assert!((general.force(z, zd).unwrap() - law).abs() < 1e-12);
}

#[test]
fn derivatives_are_those_of_the_force() {
    let models = [
        ContactModel::new(Kind::KelvinVoigt, 1800.0, 60.0).unwrap(),
        ContactModel::new(Kind::HuntCrossley, 2.5e4, 3000.0).unwrap(),
        ContactModel::new(Kind::AzadFeatherstone, 2.5e4, 1100.0).unwrap(),
        ContactModel::general(900.0, 40.0, Exponents { a: 1.2, b: 0.3, c: 1.4 }).unwrap(),
    ];
    let h = 1e-7;
    for m in &models {
        for (z, zd) in [(0.01, 0.1), (0.03, -0.02), (0.05, 0.2)] {
            let (dz, dzd) = m.derivatives(z, zd).unwrap();
            let fdz = (m.force(z + h, zd).unwrap() - m.force(z - h, zd).unwrap()) / (2.0 * h);
            let fdzd = (m.force(z, zd + h).unwrap() - m.force(z, zd - h).unwrap()) / (2.0 * h);
            assert!((dz - fdz).abs() <= 1e-5 * fdz.abs().max(1.0), "{:?} ∂f/∂z {dz} vs {fdz}", m.kind);
            assert!((dzd - fdzd).abs() <= 1e-5 * fdzd.abs().max(1.0), "{:?} ∂f/∂ż {dzd} vs {fdzd}", m.kind);
        }
        assert_eq!(m.derivatives(-0.01, 0.5).unwrap(), (0.0, 0.0), "no contact, no slope");
    }
}

#[test]
fn bad_input_is_refused() {
    let m = ContactModel::new(Kind::KelvinVoigt, 1800.0, 60.0).unwrap();
    assert!(matches!(m.deformation_for_force(-1.0), Err(ContactError::NegativeForce(_))));
    assert!(matches!(m.deformation_for_force(f64::NAN), Err(ContactError::NonFinite { .. })));
    assert!(matches!(m.force(f64::INFINITY, 0.0), Err(ContactError::NonFinite { .. })));
    assert!(matches!(m.force(0.01, f64::NAN), Err(ContactError::NonFinite { .. })));
    assert!(ContactModel::new(Kind::KelvinVoigt, -5.0, 1.0).is_err());
    assert!(ContactModel::new(Kind::KelvinVoigt, 5.0, -1.0).is_err());
    assert!(ContactModel::new(Kind::General, 5.0, 1.0).is_err());
    assert!(ContactModel::general(5.0, 1.0, Exponents { a: 0.0, b: 1.0, c: 1.0 }).is_err());
}

#[test]
fn inverse_at_rest_is_seed_001_eq_19() {
    let sponge = ContactModel::new(Kind::AzadFeatherstone, 25_044.0, 1100.0).unwrap();
    let z = sponge.deformation_for_force(224.0).unwrap();
    assert!((z - (224.0f64 / 25_044.0).powf(2.0 / 3.0)).abs() < 1e-15);
    let dice = ContactModel::new(Kind::KelvinVoigt, 1857.0, 60.0).unwrap();
    assert!((dice.deformation_for_force(104.0).unwrap() - 104.0 / 1857.0).abs() < 1e-15);
    assert_eq!(dice.deformation_for_force(0.0).unwrap(), 0.0);
}

fn any_model() -> impl Strategy<Value = ContactModel> {
    (0usize..4, 1.0f64..1e5, 0.0f64..5e3, 0.5f64..2.5).prop_map(|(i, k, l, a)| match i {
        3 => ContactModel::general(k, l, Exponents { a, b: 0.5, c: 1.0 }).unwrap(),
        i => ContactModel::new(Kind::CANDIDATES[i], k, l).unwrap(),
    })
}

proptest! {
    #[test]
    fn inverse_inverts_the_forward_model(model in any_model(), f in 0.0f64..500.0) {
        let z = model.deformation_for_force(f).unwrap();
        let back = model.force(z, 0.0).unwrap();
        prop_assert!((back - f).abs() <= 1e-9 * f.max(1.0), "f {} → z {} → f {}", f, z, back);
    }

    #[test]
    fn forward_model_inverts_the_inverse(model in any_model(), z in 0.0f64..0.1) {
        let f = model.force(z, 0.0).unwrap();
        let back = model.deformation_for_force(f).unwrap();
        prop_assert!((back - z).abs() <= 1e-9 * z.max(1e-3), "z {} → f {} → z {}", z, f, back);
    }

    #[test]
    fn force_is_never_negative(model in any_model(), z in -0.05f64..0.1, zd in -5.0f64..5.0) {
        prop_assert!(model.force(z, zd).unwrap() >= 0.0);
    }
}

#[test]
fn yaml_round_trip_keeps_everything() {
    let model = ContactModel {
        tangential: Some(Tangential::walton(3.7482, 0.9)),
        effects: vec![
            Effect::ViscoelasticRelaxation { stiffness: 800.0, time_constant: 1.5 },
            Effect::Hysteresis { fraction: 0.05, velocity_scale: 0.01 },
            Effect::SensorBias { offset: -0.4 },
        ],
        ..ContactModel::new(Kind::HertzWalton, 8.28, 0.0).unwrap()
    };
    let yaml = model.to_yaml();
    assert!(yaml.contains("kind: hertz_walton") && yaml.contains("id: viscoelastic_relaxation"), "{yaml}");
    assert_eq!(ContactModel::from_yaml(&yaml).unwrap(), model);
    // A named kind may leave its exponents out.
    let short = ContactModel::from_yaml("kind: azad_featherstone\nstiffness: 25000\ndamping: 1100\n").unwrap();
    assert_eq!(short.exponents, Exponents { a: 1.5, b: 0.5, c: 1.0 });
}

#[test]
fn an_effect_travels_as_its_id_and_its_fields_in_file_order() {
    let every = [
        Effect::ViscoelasticRelaxation { stiffness: 800.0, time_constant: 1.5 },
        Effect::Hysteresis { fraction: 0.05, velocity_scale: 0.01 },
        Effect::ContactOffsetDrift { rate: -1e-5 },
        Effect::SensorBias { offset: -0.4 },
        Effect::SensorDrift { rate: 0.004 },
        Effect::TimeDelay { delay: 0.02 },
        Effect::SensorCrosstalk { coupling: [0.01, -0.02, 0.0] },
        Effect::ToolGravity { mass: 0.3 },
        Effect::Adhesion { force: 1.5, range: 0.002 },
        Effect::QuasiLinearRelaxation { fraction: 0.4, time_constant: 2.0 },
    ];
    for effect in every {
        let list = effect.parameter_list();
        // The reference: the file's own fields, in the order the file writes them.
        let yaml: serde_yaml_ng::Mapping = serde_yaml_ng::to_value(effect).unwrap().as_mapping().unwrap().clone();
        let fields: Vec<f64> = yaml
            .iter()
            .filter(|(k, _)| k.as_str() != Some("id"))
            .flat_map(|(_, v)| match v {
                serde_yaml_ng::Value::Sequence(s) => s.iter().map(|x| x.as_f64().unwrap()).collect(),
                v => vec![v.as_f64().unwrap()],
            })
            .collect();
        assert_eq!(list, fields, "{}", effect.id());
        assert_eq!(Effect::from_parameters(effect.id(), &list).unwrap(), effect);
    }
    for (id, p, words) in [
        ("gremlins", vec![1.0], "unknown effect `gremlins`"),
        ("sensor_bias", vec![], "takes 1 parameters, not 0"),
        ("viscoelastic_relaxation", vec![1.0, 2.0, 3.0], "takes 2 parameters, not 3"),
        ("viscoelastic_relaxation", vec![1.0, f64::NAN], "finite"),
        ("hysteresis", vec![1.5, 0.01], "fraction must be in [0, 1)"),
        ("time_delay", vec![1e300], "delay must be in"),
        ("adhesion", vec![-1.0, 0.002], "force must be ≥ 0 and range > 0"),
        ("adhesion", vec![1.0, 0.0], "force must be ≥ 0 and range > 0"),
        ("adhesion", vec![1.0, f64::INFINITY], "finite"),
        ("quasi_linear_relaxation", vec![-0.1, 1.0], "fraction must be ≥ 0 and time_constant > 0"),
    ] {
        let err = Effect::from_parameters(id, &p).unwrap_err().to_string();
        assert!(err.contains(words), "{id} {p:?}: expected `{words}` in `{err}`");
    }
}

#[test]
fn yaml_mistakes_are_named() {
    for (yaml, words) in [
        ("kind: kelvin_voigt\nstiffness: 10\nexponents: {a: 1.5, b: 0, c: 1}\n", "kind kelvin_voigt has exponents"),
        ("kind: general\nstiffness: 10\n", "needs exponents"),
        ("kind: kelvin_voigt\nstiffness: -10\n", "stiffness must be > 0"),
        ("kind: springy\nstiffness: 10\n", "unknown variant `springy`"),
        ("kind: kelvin_voigt\nstiffness: 10\neffects: [{id: gremlins}]\n", "unknown variant `gremlins`"),
        ("kind: kelvin_voigt\nstiffness: 10\nstifness: 3\n", "unknown field `stifness`"),
        (
            "kind: kelvin_voigt\nstiffness: 10\neffects: [{id: viscoelastic_relaxation, stiffness: 1, time_constant: 0}]\n",
            "time_constant > 0",
        ),
    ] {
        let err = ContactModel::from_yaml(yaml).unwrap_err().to_string();
        assert!(err.contains(words), "`{yaml}`: expected `{words}` in `{err}`");
        assert_eq!(err.matches("invalid contact model").count(), 1, "said once: `{err}`");
    }
}

#[test]
fn walton_tangential_law_sticks_inside_the_cone_and_slides_outside() {
    let model = ContactModel {
        tangential: Some(Tangential::walton(3.7482, 0.5)),
        ..ContactModel::new(Kind::HertzWalton, 8.28, 0.0).unwrap()
    };
    let z: f64 = 2.0; // the snake paper works in millimetre-scale units; the law is unit-agnostic
    let fn_ = model.force(z, 0.0).unwrap();
    assert!((fn_ - 8.28 * z.powf(1.5)).abs() < 1e-12);
    let (ft, slides) = model.tangential_force(z, 0.5, fn_).unwrap().unwrap();
    assert!(!slides && (ft - 3.7482 * z.sqrt() * 0.5).abs() < 1e-12);
    let (ft, slides) = model.tangential_force(z, -20.0, fn_).unwrap().unwrap();
    assert!(slides && (ft + 0.5 * fn_).abs() < 1e-12, "{ft}");
    assert!(ContactModel::new(Kind::KelvinVoigt, 1.0, 0.0).unwrap().tangential_force(1.0, 1.0, 1.0).unwrap().is_none());
}

#[test]
fn relaxation_decays_with_its_time_constant_under_held_deformation() {
    let (km, tau, rate, dt) = (2000.0, 0.8, 0.05, 1e-3);
    let model = ContactModel {
        effects: vec![Effect::ViscoelasticRelaxation { stiffness: km, time_constant: tau }],
        ..ContactModel::new(Kind::KelvinVoigt, 1800.0, 0.0).unwrap()
    };
    let mut state = model.effect_state();
    // Press at constant rate for 0.4 s (from 1 mm deep), then hold for 3 s.
    let mut z = 0.001;
    for _ in 0..400 {
        z += rate * dt;
        model.step(&mut state, z, rate, dt).unwrap();
    }
    let branch_at_hold = km * rate * tau * (1.0 - (-0.4f64 / tau).exp());
    assert!(
        (state.branch_force[0] - branch_at_hold).abs() < 1e-9 * branch_at_hold,
        "{} vs {}",
        state.branch_force[0],
        branch_at_hold
    );
    let mut last = 0.0;
    for _ in 0..3000 {
        last = model.step(&mut state, z, 0.0, dt).unwrap().0;
    }
    let expected = 1800.0 * z + branch_at_hold * (-3.0f64 / tau).exp();
    assert!((last - expected).abs() < 1e-9 * expected, "held force {last} vs {expected}");
}

#[test]
fn hysteresis_and_sensor_effects_change_what_they_should() {
    let base = ContactModel::new(Kind::KelvinVoigt, 1800.0, 0.0).unwrap();
    let model = ContactModel {
        effects: vec![
            Effect::Hysteresis { fraction: 0.1, velocity_scale: 1e-3 },
            Effect::SensorBias { offset: 0.7 },
            Effect::SensorDrift { rate: 0.01 },
        ],
        ..base.clone()
    };
    let mut state = model.effect_state();
    let (loading, _) = model.step(&mut state, 0.03, 0.05, 0.0).unwrap();
    let (unloading, measured) = model.step(&mut state, 0.03, -0.05, 2.0).unwrap();
    assert!(loading > unloading, "loading path above unloading");
    assert!((loading - unloading - 2.0 * 0.1 * 54.0 * (50.0f64).tanh()).abs() < 1e-9);
    assert!((measured - unloading - (0.7 + 0.01 * 2.0)).abs() < 1e-12, "bias + drift after 2 s");
}

#[test]
fn a_time_delay_shifts_the_whole_reading_by_its_delay() {
    // A ramp of force read 25 ms late: at 1 kHz the reading at t is the force at t − 0.025 (exactly, the
    // ramp being linear), and the first reading stands before the line is full.
    let base = ContactModel::new(Kind::KelvinVoigt, 1000.0, 0.0).unwrap();
    let model = ContactModel { effects: vec![Effect::TimeDelay { delay: 0.025 }], ..base };
    let mut state = model.effect_state();
    let dt = 1e-3;
    for i in 1..=200 {
        let t = i as f64 * dt;
        let (surface, measured) = model.step(&mut state, 0.01 * t, 0.01, dt).unwrap();
        assert!((surface - 10.0 * t).abs() < 1e-9);
        let expected = 10.0 * (t - 0.025).max(dt);
        assert!((measured - expected).abs() < 1e-9, "t {t}: read {measured}, expected {expected}");
    }
    assert!(state.delay_line.len() <= 27, "the line keeps only the delay's span: {}", state.delay_line.len());
    // Steps far finer than the delay: the line stays bounded.
    let mut state = model.effect_state();
    for _ in 0..3 * DELAY_LINE {
        model.step(&mut state, 0.01, 0.0, 1e-7).unwrap();
    }
    assert!(state.delay_line.len() <= DELAY_LINE);
    for bad in [-1e-3, 1.5, f64::NAN] {
        let m = ContactModel { effects: vec![Effect::TimeDelay { delay: bad }], ..model.clone() };
        assert!(m.validate().is_err(), "delay {bad} accepted");
    }
}

#[test]
fn crosstalk_and_tool_weight_add_to_the_normal_reading() {
    let base = ContactModel::new(Kind::KelvinVoigt, 1000.0, 0.0).unwrap();
    let model = ContactModel {
        effects: vec![Effect::SensorCrosstalk { coupling: [0.02, -0.01, 0.0] }, Effect::ToolGravity { mass: 0.3 }],
        ..base
    };
    let mut state = model.effect_state();
    let surface = model.step_surface(&mut state, 0.02, 0.0, 1e-3).unwrap();
    let inputs = SensorInputs { tangential_force: [10.0, 5.0, 0.0], gravity_change: -0.5 };
    let read = model.sense(&mut state, surface, &inputs).unwrap();
    assert!((read - (20.0 + 0.2 - 0.05 + 0.3 * -0.5)).abs() < 1e-12, "{read}");
    let nan = SensorInputs { tangential_force: [f64::NAN, 0.0, 0.0], ..inputs };
    assert!(model.sense(&mut state, surface, &nan).is_err());
    let bad = ContactModel { effects: vec![Effect::SensorCrosstalk { coupling: [0.6, 0.0, 0.0] }], ..model.clone() };
    assert!(bad.validate().is_err());
}

#[test]
fn gravity_change_is_zero_at_the_tare_orientation_and_follows_a_tilt() {
    let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let (g, n) = ([0.0, 0.0, -9.81], [0.0, 0.0, -1.0]);
    assert_eq!(gravity_change(&identity, &identity, g, n), 0.0);
    // Tilted by θ about x after a tare facing down: gravity along the sensor's old normal axis is g cos θ,
    // so the change along n is 9.81 (cos θ − 1) — a hand that weighs m more than compensated reads m·that.
    let th: f64 = 0.2;
    let (c, s) = (th.cos(), th.sin());
    let tilted = [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]];
    let change = gravity_change(&tilted, &identity, g, n);
    assert!((change - 9.81 * (c - 1.0)).abs() < 1e-12, "{change}");
    // Tared tilted, back level: the opposite sign.
    assert!((gravity_change(&identity, &tilted, g, n) - 9.81 * (c - 1.0)).abs() < 1e-12);
}

/// The branch force of ṡ = k_m ż − s/τ under z = A sin ωt from rest, in closed form.
fn branch_under_sine(km: f64, tau: f64, amp: f64, w: f64, t: f64) -> f64 {
    let wt = w * tau;
    let steady = |t: f64| km * amp * w * tau * ((w * t).cos() + wt * (w * t).sin()) / (1.0 + wt * wt);
    steady(t) - steady(0.0) * (-t / tau).exp()
}

#[test]
fn a_relaxation_branch_sampled_at_100_hz_follows_its_closed_form_to_second_order() {
    // A 0.15 s branch under 1 Hz pushes, stepped at 100 Hz and 200 Hz with the measured deformation and
    // rate: the update driven by the deformation's change is within 0.1 % of the closed form and its error
    // falls fourfold when the step halves (second order). Holding the rate over the step instead leads the
    // branch by half a step: 3 % at 100 Hz.
    let (km, tau, amp, w) = (2500.0, 0.15, 0.02, 2.0 * std::f64::consts::PI);
    let model = ContactModel {
        effects: vec![Effect::ViscoelasticRelaxation { stiffness: km, time_constant: tau }],
        ..ContactModel::new(Kind::KelvinVoigt, 1.0, 0.0).unwrap()
    };
    let worst = |rate: f64| {
        let dt = 1.0 / rate;
        let mut state = model.effect_state();
        // In contact throughout: the deformation rides 5 cm deep (the base law does not enter the branch).
        let depth = 0.05;
        model.step(&mut state, depth, 0.0, 0.0).unwrap();
        let mut worst: f64 = 0.0;
        for i in 1..=(3.0 * rate) as usize {
            let t = i as f64 * dt;
            let (z, zdot) = (depth + amp * (w * t).sin(), amp * w * (w * t).cos());
            model.step(&mut state, z, zdot, dt).unwrap();
            worst = worst.max((state.branch_force[0] - branch_under_sine(km, tau, amp, w, t)).abs());
        }
        worst
    };
    let scale = km * amp * w * tau;
    let (at_100, at_200) = (worst(100.0), worst(200.0));
    assert!(at_100 < 1e-3 * scale, "error {at_100} N at 100 Hz (scale {scale} N)");
    assert!((at_100 / at_200 - 4.0).abs() < 0.5, "errors {at_100} and {at_200} N: not second order");
}

#[test]
fn maxwell_step_is_exact_for_a_ramp_and_a_hold() {
    let (tau, dt, change) = (0.3, 0.01, 2e-4);
    // A ramp from rest: s = k_m v τ (1 − e^(−t/τ)) after one step of rate v = change/dt.
    let s = softcontact_contact::maxwell_step(0.0, 1000.0 * change, dt, tau);
    let exact = 1000.0 * (change / dt) * tau * (1.0 - (-dt / tau).exp());
    assert!((s - exact).abs() < 1e-12 * exact);
    // A hold decays; a step of the deformation alone (dt = 0) is the spring's.
    assert!((softcontact_contact::maxwell_step(s, 0.0, dt, tau) - s * (-dt / tau).exp()).abs() < 1e-15);
    assert_eq!(softcontact_contact::maxwell_step(1.0, 0.5, 0.0, tau), 1.5);
}

/// The pull a press to `peak` and a retract to z leaves, written out: F·min(1, (peak − z)/(peak + δ)) while
/// z ≥ −δ, nothing beyond.
fn adhesion_by_hand(force: f64, range: f64, peak: f64, z: f64) -> f64 {
    if z < -range { 0.0 } else { force * ((peak - z) / (peak + range)).clamp(0.0, 1.0) }
}

#[test]
fn adhesion_pulls_on_the_way_out_lets_go_at_its_range_and_not_while_pressing() {
    let (force, range, k) = (2.0, 0.004, 1e4);
    let mut model = ContactModel::new(Kind::KelvinVoigt, k, 0.0).unwrap();
    model.effects = vec![Effect::Adhesion { force, range }];
    let mut state = model.effect_state();
    let dt = 1e-3;
    // Press to 10 mm at 10 mm/s: the law alone.
    let mut z = -0.002;
    while z < 0.01 - 1e-12 {
        z += 1e-5;
        let (surface, _) = model.step(&mut state, z, 0.01, dt).unwrap();
        assert!((surface - k * z.max(0.0)).abs() < 1e-9, "pressing at {z}: {surface}");
    }
    // Out to 8 mm beyond the surface: law minus the pull until −range, then nothing.
    let peak = z;
    let mut let_go = false;
    while z > -0.008 {
        z -= 1e-5;
        let (surface, _) = model.step(&mut state, z, -0.01, dt).unwrap();
        let expected = k * z.max(0.0) - if let_go { 0.0 } else { adhesion_by_hand(force, range, peak, z) };
        assert!((surface - expected).abs() < 1e-9, "retracting at {z}: {surface} vs {expected}");
        let_go |= z < -range;
    }
    assert!(state.adhesion_peak.is_none(), "let go beyond its range");
    // At −range (just before letting go) the pull was the whole pull-off force.
    assert!((adhesion_by_hand(force, range, peak, -range) - force).abs() < 1e-12);
    // Back in: a fresh contact, pressed, pulls nothing.
    while z < 0.005 {
        z += 1e-5;
        let (surface, _) = model.step(&mut state, z, 0.01, dt).unwrap();
        assert!((surface - k * z.max(0.0)).abs() < 1e-9, "pressing again at {z}: {surface}");
    }
}

#[test]
fn adhesion_at_rest_is_the_step_and_its_slope_the_difference_quotient() {
    let mut model = ContactModel::new(Kind::HuntCrossley, 2e4, 100.0).unwrap();
    model.effects = vec![Effect::Adhesion { force: 3.0, range: 0.003 }];
    let mut state = model.effect_state();
    for i in 0..=100 {
        model.step(&mut state, 0.0002 * i as f64, 0.2, 1e-3).unwrap();
    }
    for i in 0..=50 {
        model.step(&mut state, 0.02 - 0.0002 * i as f64, -0.2, 1e-3).unwrap();
    }
    for z in [0.012, 0.005, 0.0005, -0.001, -0.0029, 0.019, 0.025] {
        let (at_rest, slope) = model.force_at_rest(&state, z, 0.0).unwrap();
        let mut copy = state.clone();
        let stepped = model.step_surface(&mut copy, z, 0.0, 0.0).unwrap();
        assert!((at_rest - stepped).abs() < 1e-9, "z {z}: at rest {at_rest}, stepped {stepped}");
        let h = 1e-7;
        let quotient = (model.force_at_rest(&state, z + h, 0.0).unwrap().0
            - model.force_at_rest(&state, z - h, 0.0).unwrap().0)
            / (2.0 * h);
        assert!((slope - quotient).abs() <= 1e-4 * quotient.abs().max(1.0), "z {z}: slope {slope} vs {quotient}");
        assert!(slope > 0.0, "the force grows with z at {z}: {slope}");
    }
}

/// The sensor reads the medium's drag of the step's rate, less the drag of the speed its zero was read
/// at, in contact and out of it; the surface force is untouched and a reading less `sensor_offset` is it.
#[test]
fn a_medium_drag_is_read_at_the_steps_rate_less_its_tare_speed_in_and_out_of_contact() {
    let (damping, tare_speed) = (8.0, 0.01);
    let mut model = ContactModel::new(Kind::KelvinVoigt, 1e4, 0.0).unwrap();
    let plain = model.clone();
    model.effects = vec![Effect::MediumDrag { damping, tare_speed }];
    let (mut state, mut plain_state) = (model.effect_state(), plain.effect_state());
    for (z, zdot) in [(-0.004, 0.03), (-0.001, 0.01), (0.002, 0.02), (0.003, 0.0), (0.001, -0.05), (-0.002, -0.05)] {
        let (surface, measured) = model.step(&mut state, z, zdot, 1e-3).unwrap();
        let (plain_surface, _) = plain.step(&mut plain_state, z, zdot, 1e-3).unwrap();
        assert_eq!(surface, plain_surface, "the drag acts on the hand, not in the surface's force");
        let drag = damping * (zdot - tare_speed);
        assert!((measured - (surface + drag)).abs() <= 1e-12, "at ({z}, {zdot}): {measured} vs {}", surface + drag);
        assert!((measured - model.sensor_offset(&state) - surface).abs() <= 1e-12);
    }
    model.plausible().unwrap();
    for (damping, tare_speed, words) in [
        (150.0, 0.0, "more than 100 N·s/m"),
        (-1.0, 0.0, "damping must be ≥ 0, not -1"),
        (1.0, 2.0, "at most 1 m/s, not 2"),
    ] {
        model.effects = vec![Effect::MediumDrag { damping, tare_speed }];
        let err = model.plausible().unwrap_err().to_string();
        assert!(err.contains(words), "{damping} N·s/m at {tare_speed} m/s: {err}");
    }
    model.effects = vec![Effect::MediumDrag { damping: 60.0, tare_speed: 0.0 }; 2];
    assert!(model.plausible().unwrap_err().to_string().contains("in all"));
    let file = "kind: kelvin_voigt\nstiffness: 1.0e4\ndamping: 0.0\neffects:\n  - {id: medium_drag, damping: 8.0, tare_speed: 0.01}\n";
    assert_eq!(ContactModel::from_yaml(file).unwrap().effects, [Effect::MediumDrag { damping: 8.0, tare_speed: 0.01 }]);
}

/// A squeeze film's drag is read at the step's rate with the share reach / (gap + reach) of its damping:
/// the whole in contact, half at one reach from the surface, a tenth at nine; the surface force is
/// untouched, a reading less `sensor_offset` is it, and its damping in contact counts toward the medium's
/// bound.
#[test]
fn a_squeeze_film_drags_with_all_of_its_damping_in_contact_and_half_of_it_one_reach_away() {
    let (damping, reach) = (30.0, 2e-3);
    let mut model = ContactModel::new(Kind::HuntCrossley, 1e5, 1e3).unwrap();
    let plain = model.clone();
    model.effects = vec![Effect::SqueezeFilm { damping, reach }];
    let (mut state, mut plain_state) = (model.effect_state(), plain.effect_state());
    for (z, zdot, share) in
        [(-18e-3, 0.03, 0.1), (-2e-3, 0.01, 0.5), (0.0, 0.02, 1.0), (3e-3, -0.02, 1.0), (-2e-3, -0.05, 0.5)]
    {
        let (surface, measured) = model.step(&mut state, z, zdot, 1e-3).unwrap();
        let (plain_surface, _) = plain.step(&mut plain_state, z, zdot, 1e-3).unwrap();
        assert_eq!(surface, plain_surface, "the film's drag acts on the hand, not in the surface's force");
        let drag = share * damping * zdot;
        assert!((measured - (surface + drag)).abs() <= 1e-12, "at ({z}, {zdot}): {measured} vs {}", surface + drag);
        assert!((measured - model.sensor_offset(&state) - surface).abs() <= 1e-12);
    }
    model.plausible().unwrap();
    for (damping, reach, words) in [
        (150.0, 1e-3, "more than 100 N·s/m"),
        (-1.0, 1e-3, "damping must be ≥ 0 and reach > 0"),
        (1.0, 0.0, "damping must be ≥ 0 and reach > 0"),
        (1.0, 0.5, "farther than 0.02 m"),
        (f64::NAN, 1e-3, "finite"),
    ] {
        model.effects = vec![Effect::SqueezeFilm { damping, reach }];
        let err = model.plausible().unwrap_err().to_string();
        assert!(err.contains(words), "{damping} N·s/m reaching {reach} m: {err}");
    }
    model.effects =
        vec![Effect::SqueezeFilm { damping: 60.0, reach: 1e-3 }, Effect::MediumDrag { damping: 60.0, tare_speed: 0.0 }];
    assert!(model.plausible().unwrap_err().to_string().contains("in all"));
    let file = "kind: kelvin_voigt\nstiffness: 1.0e4\neffects:\n  - {id: squeeze_film, damping: 30.0, reach: 0.002}\n";
    let read = ContactModel::from_yaml(file).unwrap().effects;
    assert_eq!(read, [Effect::SqueezeFilm { damping: 30.0, reach: 2e-3 }]);
    assert_eq!(Effect::from_parameters("squeeze_film", &read[0].parameter_list()).unwrap(), read[0]);
}

#[test]
fn adhesion_beyond_what_a_surface_can_pull_is_implausible() {
    let mut model = ContactModel::new(Kind::KelvinVoigt, 1e4, 0.0).unwrap();
    model.effects = vec![Effect::Adhesion { force: 5.0, range: 0.002 }];
    model.plausible().unwrap();
    for (force, range, words) in [(60.0, 0.002, "more than 50 N"), (5.0, 0.05, "farther than 0.02 m")] {
        model.effects = vec![Effect::Adhesion { force, range }];
        let err = model.plausible().unwrap_err().to_string();
        assert!(err.contains(words), "{force} N, {range} m: {err}");
    }
    model.effects = vec![Effect::Adhesion { force: 30.0, range: 0.002 }; 2];
    assert!(model.plausible().unwrap_err().to_string().contains("in all"));
}

/// A finite model file the controller must still refuse: an exponent of 5 (the simulator's and the
/// controller's law takes 0 to 4) and a tangential law of 1e300 N/m^1.5 (finite, so `validate` passes).
#[test]
fn exponents_beyond_four_and_a_tangential_stiffness_of_1e300_are_implausible() {
    let mut model = ContactModel::general(2.5e4, 1400.0, Exponents { a: 1.5, b: 0.5, c: 1.0 }).unwrap();
    model.tangential = Some(Tangential::walton(1e5, 0.8));
    model.plausible().unwrap();
    for exponents in [Exponents { a: 5.0, b: 0.5, c: 1.0 }, Exponents { a: 1.5, b: 0.5, c: 10.0 }] {
        let err = ContactModel { exponents, ..model.clone() }.plausible().unwrap_err().to_string();
        assert!(err.contains("outside 0.0..=4.0"), "{exponents:?}: {err}");
    }
    for stiffness in [1e300, 1e12] {
        let t = Some(Tangential::walton(stiffness, 50.0));
        let err = ContactModel { tangential: t, ..model.clone() }.plausible().unwrap_err().to_string();
        assert!(err.contains("tangential stiffness"), "{stiffness}: {err}");
    }
}

#[test]
fn quasi_linear_relaxation_is_fungs_reduced_relaxation_on_the_elastic_force() {
    // A step to z₀ then a hold: f(t) = k z₀ᵃ (1 + g e^{−t/τ}) (Fung's G(t) = 1 + g e^{−t/τ}).
    let (k, g, tau, z0) = (2e4, 0.6, 0.5, 0.02);
    let mut model = ContactModel::new(Kind::HuntCrossley, k, 0.0).unwrap();
    model.effects = vec![Effect::QuasiLinearRelaxation { fraction: g, time_constant: tau }];
    let mut state = model.effect_state();
    let dt = 1e-5;
    model.step_surface(&mut state, 0.0, 0.0, dt).unwrap();
    model.step_surface(&mut state, z0, z0 / dt, dt).unwrap();
    let mut t = 0.0;
    for _ in 0..200 {
        let hold = 0.01;
        let force = model.step_surface(&mut state, z0, 0.0, hold).unwrap();
        t += hold;
        let fung = k * z0.powf(1.5) * (1.0 + g * (-t / tau).exp());
        assert!((force / fung - 1.0).abs() < 1e-4, "t {t}: {force} N, Fung {fung} N");
    }
    // The branch is the elastic force's, not the deformation's: at twice the depth, 2^1.5 times the force.
    let at = |z: f64| {
        let mut state = model.effect_state();
        model.step_surface(&mut state, 0.0, 0.0, dt).unwrap();
        model.step_surface(&mut state, z, z / dt, dt).unwrap() - k * z.powf(1.5)
    };
    assert!((at(2.0 * z0) / at(z0) - 2f64.powf(1.5)).abs() < 1e-3);
    // At rest: the step, and its slope the difference quotient.
    for z in [0.019, 0.03] {
        let (f, slope) = model.force_at_rest(&state, z, 0.001).unwrap();
        let stepped = model.step_surface(&mut state.clone(), z, 0.0, 0.001).unwrap();
        assert!((f - stepped).abs() < 1e-9 * f.abs().max(1.0), "z {z}: {f} vs {stepped}");
        let h = 1e-7;
        let q = (model.force_at_rest(&state, z + h, 0.001).unwrap().0
            - model.force_at_rest(&state, z - h, 0.001).unwrap().0)
            / (2.0 * h);
        assert!((slope / q - 1.0).abs() < 1e-5, "z {z}: slope {slope} vs {q}");
    }
}

#[test]
fn on_a_linear_law_a_quasi_linear_branch_is_a_maxwell_branch_of_g_k() {
    let (k, g, tau) = (3000.0, 0.3, 0.4);
    let mut quasi = ContactModel::new(Kind::KelvinVoigt, k, 20.0).unwrap();
    quasi.effects = vec![Effect::QuasiLinearRelaxation { fraction: g, time_constant: tau }];
    let mut maxwell = quasi.clone();
    maxwell.effects = vec![Effect::ViscoelasticRelaxation { stiffness: g * k, time_constant: tau }];
    let (mut a, mut b) = (quasi.effect_state(), maxwell.effect_state());
    for i in 0..3000 {
        let t = i as f64 * 1e-3;
        let (z, zd) = (0.01 * (1.0 - (3.0 * t).cos()) - 0.002, 0.03 * (3.0 * t).sin());
        let (fa, fb) =
            (quasi.step_surface(&mut a, z, zd, 1e-3).unwrap(), maxwell.step_surface(&mut b, z, zd, 1e-3).unwrap());
        assert!((fa - fb).abs() < 1e-9 * fb.abs().max(1.0), "t {t}: {fa} vs {fb}");
    }
}
