//! The foreign-effect corpus: recordings of the lockstep cell whose hidden effect is written outside the
//! library the workflow fits — the surface's in `softcontact_sim::foreign` (a Prony series of three
//! branches, Fung's quasi-linear viscoelasticity with a two-term reduced relaxation function, Bouc–Wen
//! hysteresis), the sensor's in `softcontact_sim::FtSensorConfig` (its frame turned about an arbitrary
//! axis, a lag that is no whole number of steps, an exponential warm-up, Ornstein–Uhlenbeck noise). The
//! library has each only nearly (one Maxwell branch per named relaxation, Fung's one-term form, a tanh loop,
//! a coupling of the normal reading with the tangential load, a delay, a linear drift): every case has a
//! fixed expected answer, the library id nearest to what was hidden. As expected means: the named set is the
//! expected one, the gap shrinks by at least 60 % of the ideal, and the parameters checked are within
//! their tolerance. Beside them, baselines of the wrong kind given instead of identify's: the answer
//! re-chooses the kind, and names only what is hidden.

use nalgebra::{UnitQuaternion, Vector3};
use softcontact_contact::{ContactModel, Effect, Kind};
use softcontact_dynamics::lwr4;
use softcontact_sim::FtSensorConfig;
use softcontact_sim::foreign::ForeignEffect;

use super::corpus::{Case, DICE, ExpectedParameter, SPONGE, gripping};
use super::experiment::Across;

/// The least shrink of an answer as expected (issue 37).
const MIN_SHRINK_OF_IDEAL: f64 = 0.6;

/// The corpus, seeds from 1001 on (today's corpus keeps its own).
pub fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    let gamma = FtSensorConfig::gamma;
    for (law, base, geometry, scale) in
        [("sponge", softcontact_sim::sponge(), SPONGE, 1.0), ("dice", softcontact_sim::dice(), DICE, 0.25)]
    {
        // Branches of a fifth, a tenth and a fifteenth of the law's slope mid-range (sponge ≈ 6.5 kN/m at
        // 3 cm; dice 1.9 kN/m), at 0.3, 1.5 and 6 s.
        let prony =
            ForeignEffect::Prony { branches: vec![(1300.0 * scale, 0.3), (650.0 * scale, 1.5), (430.0 * scale, 6.0)] };
        push(
            &mut out,
            format!("{law}: Prony series of three branches (0.3, 1.5, 6 s)"),
            base.clone(),
            vec![prony],
            gamma(),
            geometry,
            vec!["viscoelastic_relaxation"],
        );
        push(
            &mut out,
            format!("{law}: Fung's quasi-linear viscoelasticity, G = 0.85 + 0.08 e^(−t/0.5) + 0.07 e^(−t/3)"),
            base.clone(),
            vec![ForeignEffect::QuasiLinear { branches: vec![(0.08, 0.5), (0.07, 3.0)] }],
            gamma(),
            geometry,
            // On the dice's linear law Fung's form is a Prony series exactly: the default form is the answer.
            vec![if law == "dice" { "viscoelastic_relaxation" } else { "quasi_linear_relaxation" }],
        );
        push(
            &mut out,
            format!("{law}: Bouc–Wen hysteresis, 2 % of the force limit over 1 mm"),
            base.clone(),
            vec![ForeignEffect::BoucWen { force: 0.02 * geometry.1, travel: 0.001, exponent: 1.0 }],
            gamma(),
            geometry,
            vec!["hysteresis"],
        );
        sensor_cases(&mut out, law, &base, geometry);
    }
    // Creep: one long hold at a held force on a Prony surface identified earlier without it.
    push(
        &mut out,
        "sponge: creep under a held force (Prony series, 40 s hold)".into(),
        softcontact_sim::sponge(),
        vec![ForeignEffect::Prony { branches: vec![(1300.0, 0.3), (650.0, 1.5), (430.0, 6.0)] }],
        gamma(),
        SPONGE,
        vec!["viscoelastic_relaxation"],
    )
    .hold = Some(40.0);
    wrong_kinds(&mut out);
    for c in out.iter_mut() {
        c.visible_in = visible_in(&c.expected);
        if c.given_kind.is_some() {
            c.visible_in = "moves at several speeds (the damping's form)";
        }
    }
    out
}

/// A wrong baseline given instead of identify's (issue 37: fixed, not patched): the sponge's law
/// (Azad–Featherstone's damping, λ z^{1/2} ż) given as Hunt–Crossley (λ z^{3/2} ż), alone and under a
/// relaxation branch of the library's own form; the dice's linear law given as Hunt–Crossley. Each answer
/// re-chooses the truth's kind and names what is hidden, nothing else.
fn wrong_kinds(out: &mut Vec<Case>) {
    let gamma = FtSensorConfig::gamma;
    let branch = Effect::ViscoelasticRelaxation { stiffness: 1300.0, time_constant: 1.0 };
    let mut relaxing = softcontact_sim::sponge();
    relaxing.effects.push(branch);
    for (name, truth, geometry, expected) in [
        ("sponge: the law given as hunt_crossley (it is azad_featherstone)", softcontact_sim::sponge(), SPONGE, vec![]),
        (
            "sponge: the law given as hunt_crossley, a relaxation branch of 1.3 kN/m and 1 s hidden",
            relaxing,
            SPONGE,
            vec!["viscoelastic_relaxation"],
        ),
        ("dice: the law given as hunt_crossley (it is kelvin_voigt)", softcontact_sim::dice(), DICE, vec![]),
    ] {
        push(out, name.into(), truth, vec![], gamma(), geometry, expected).given_kind = Some(Kind::HuntCrossley);
    }
}

/// The sensor's foreign effects on `law` (`base`): a warm-up, a lag between steps, the frame turned about
/// an arbitrary axis, and Ornstein–Uhlenbeck nulls.
fn sensor_cases(out: &mut Vec<Case>, law: &str, base: &ContactModel, geometry: ((f64, f64), f64)) {
    let gamma = FtSensorConfig::gamma;
    // A Gamma warming up: 1.5 N (sponge; dice 1 N) settling over a minute, the record's tares
    // taking out what it reached by then.
    let warm = if law == "sponge" { 1.5 } else { 1.0 };
    push(
        out,
        format!("{law}: sensor warming up, {warm} N settling with τ 60 s"),
        base.clone(),
        vec![],
        FtSensorConfig {
            warm_up: [0.6 * warm, -0.4 * warm, warm, 0.01, -0.01, 0.005],
            warm_up_time_constant: 60.0,
            ..gamma()
        },
        geometry,
        vec!["sensor_drift"],
    );
    let delay = if law == "sponge" { 0.0173 } else { 0.0127 };
    push(
        out,
        format!("{law}: the whole wrench read {:.1} ms late", delay * 1e3),
        base.clone(),
        vec![],
        FtSensorConfig { delay, ..gamma() },
        geometry,
        vec!["time_delay"],
    )
    .parameters
    .push(ExpectedParameter {
        id: "time_delay",
        names: vec!["delay_s"],
        truth: vec![delay],
        tolerance: 0.0005,
        unit: ("ms", 1e-3),
    });
    let (axis, angle) =
        if law == "sponge" { (Vector3::new(0.6, -0.8, 0.35), 1.0f64) } else { (Vector3::new(-0.3, 0.5, 0.81), 0.7) };
    let (sensor, coupling) = turned(axis, angle.to_radians());
    let case = push(
        out,
        format!("{law}: sensor turned {angle}° about ({}, {}, {})", axis.x, axis.y, axis.z),
        gripping(base.clone()),
        vec![],
        sensor,
        geometry,
        vec!["sensor_crosstalk"],
    );
    case.across = Across::AlongXAndY;
    case.parameters.push(ExpectedParameter {
        id: "sensor_crosstalk",
        names: vec!["coupling_x", "coupling_y", "coupling_z"],
        truth: coupling.to_vec(),
        tolerance: 0.05f64.to_radians(),
        unit: ("°", 1f64.to_radians()),
    });
    for time_constant in [0.2, 2.0] {
        push(
            out,
            format!("null: {law}, Ornstein–Uhlenbeck noise ({time_constant} s) as large as the white"),
            base.clone(),
            vec![],
            FtSensorConfig { coloured_noise: gamma().noise, coloured_time_constant: time_constant, ..gamma() },
            geometry,
            vec![],
        );
    }
}

/// A case of `out`'s next seed, with no sway, tilt or parameter checked yet.
fn push<'a>(
    out: &'a mut Vec<Case>,
    name: String,
    truth: ContactModel,
    foreign: Vec<ForeignEffect>,
    sensor: FtSensorConfig,
    (push, max_force): ((f64, f64), f64),
    expected: Vec<&'static str>,
) -> &'a mut Case {
    let seed = 1001 + out.len() as u64;
    let case = Case::new(name, truth, sensor, (push, max_force), expected, seed);
    out.push(Case { foreign, min_shrink_of_ideal: MIN_SHRINK_OF_IDEAL, ..case });
    out.last_mut().expect("just pushed")
}

/// The excitation that shows each expected id.
fn visible_in(expected: &[&str]) -> &'static str {
    match expected.first().copied() {
        None => "- (coloured noise)",
        Some("viscoelastic_relaxation" | "quasi_linear_relaxation") => "holds after moves",
        Some("hysteresis") => "loading against unloading (pushes)",
        Some("sensor_drift") => "free space between runs, tares",
        Some("time_delay") => "stops and lift-offs",
        Some("sensor_crosstalk") => "sway along x and y at a held force",
        Some(_) => "-",
    }
}

/// The Gamma mounted turned by `angle` about the world axis `axis` (as it is with the hand at the cell's
/// start; the hand keeps that orientation in contact), and the coupling the normal reading then has with
/// the tangential load on the hand: the world reads F − ω×F, so the normal reading f gains F·(n × ω).
fn turned(axis: Vector3<f64>, angle: f64) -> (FtSensorConfig, [f64; 3]) {
    let arm = lwr4::model();
    let mut data = arm.data();
    arm.forward_kinematics(&mut data, &softcontact_sim::DEFAULT_Q);
    let frame = arm.frame_id(lwr4::FT_SENSOR_FRAME).expect("the URDF's sensor frame");
    let sensor = arm.frame_pose(&data, frame).rotation;
    let world = axis.normalize() * angle;
    let mounting = UnitQuaternion::from_scaled_axis(sensor.inverse() * world);
    let normal = Vector3::new(0.0, 0.0, -1.0);
    let coupling = normal.cross(&world);
    (FtSensorConfig { mounting, ..FtSensorConfig::gamma() }, [coupling.x, coupling.y, coupling.z])
}
