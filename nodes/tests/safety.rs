//! The safety contract in the lockstep cell (docs/safety.md): from a hand pressing the sponge, every
//! bad input a user, a file or a stranger can send the controller is refused, and the arm stays put —
//! the hand moves less than 5 mm, every joint stays within its position, velocity and torque limits,
//! and the true contact force (the simulator's) never passes `force_limit`. Then a fuzz of the same
//! inputs, random and extreme, accepted or not, checked against the same physical invariants
//! (`SOFTCONTACT_FUZZ_CASES`, default 1000).

// `!(x <= limit)` on purpose: a NaN is a violation too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::Vector3;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use softcontact_contact::{ContactModel, Exponents, Kind};
use softcontact_dynamics::lwr4;
use softcontact_nodes::contact_estimator::{ContactEstimatorNode, EstimatorConfig};
use softcontact_nodes::deformation_controller::{ControllerConfig, DeformationController};
use softcontact_sim::{SimConfig, Simulator};
use softcontact_simcell::cell::Cell;

const MAX_FORCE: f64 = 250.0;
const FORCE_LIMIT: f64 = 1.2 * MAX_FORCE;

/// The cell with the hand pressing the sponge at 60 N, settled; the controller knows the sponge.
fn pressing(seed: u64) -> Cell {
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), seed);
    config.sensor = softcontact_sim::FtSensorConfig::gamma();
    let controller =
        DeformationController::new(ControllerConfig::lwr4(MAX_FORCE, 0.06), softcontact_sim::sponge()).unwrap();
    let estimator = ContactEstimatorNode::new(EstimatorConfig::default()).unwrap();
    let mut cell = Cell::new(config, controller, estimator).unwrap();
    let mut cycles = 0;
    while !cell.cycle().unwrap().is_some_and(|t| t.controller.in_contact) {
        cycles += 1;
        assert!(cycles < 10_000, "no contact");
    }
    cell.controller.law.command_force(60.0, 1.0).unwrap();
    run(&mut cell, 1500);
    cell
}

/// The physical invariants of one cycle; the first violation, if any.
fn violation(sim: &Simulator) -> Option<String> {
    violation_within(sim, FORCE_LIMIT)
}

/// The same, with the contact force bounded by `force_bound`.
fn violation_within(sim: &Simulator, force_bound: f64) -> Option<String> {
    let model = lwr4::model();
    for (i, j) in model.joints.iter().enumerate() {
        let (q, dq, tau) = (sim.q()[i], sim.dq()[i], sim.applied_torque()[i]);
        if !(q >= j.limits.lower && q <= j.limits.upper) {
            return Some(format!("joint {} at {q} rad, limits [{}, {}]", i + 1, j.limits.lower, j.limits.upper));
        }
        if !(dq.abs() <= j.limits.velocity) {
            return Some(format!("joint {} at {dq} rad/s, limit {}", i + 1, j.limits.velocity));
        }
        // The KRC adds its own gravity to what the driver sends: allow its share above the limit.
        if !(tau.abs() <= 1.5 * j.limits.effort) {
            return Some(format!("joint {} torque {tau} N·m, limit {}", i + 1, j.limits.effort));
        }
    }
    let f = sim.contact().normal_force;
    (!(f <= force_bound)).then(|| format!("contact force {f} N above the force limit {force_bound} N"))
}

/// Runs `cycles` cycles checking the invariants; the largest distance of the hand from where it was.
fn run(cell: &mut Cell, cycles: usize) -> f64 {
    let start = cell.lockstep.sim.tool_pose().translation.vector;
    let mut farthest: f64 = 0.0;
    for k in 0..cycles {
        cell.cycle().unwrap();
        if let Some(v) = violation(&cell.lockstep.sim) {
            panic!("cycle {k}: {v}");
        }
        farthest = farthest.max((cell.lockstep.sim.tool_pose().translation.vector - start).norm());
    }
    farthest
}

/// Refused inputs leave the hand where it was: less than 5 mm in 2 s.
fn assert_stays_put(cell: &mut Cell, what: &str) {
    let moved = run(cell, 2000);
    assert!(moved < 5e-3, "{what}: the hand moved {:.1} mm", moved * 1e3);
}

#[test]
fn commands_outside_their_physical_range_are_refused_and_the_arm_stays_put() {
    // Class 1: `softcontact force 60 --duration 1e200` made the quintic NaN and swept the hand 1 m.
    let mut cell = pressing(21);
    for duration in [1e200, 1e154, 1e61, 601.0, f64::INFINITY, f64::NAN, 0.0, -1.0, 1e-300, 0.01] {
        assert!(cell.controller.law.command_force(60.0, duration).is_err(), "duration {duration}");
        assert!(cell.controller.law.command_force(100.0, duration).is_err(), "duration {duration}");
        assert!(cell.controller.law.command_deformation(0.01, duration).is_err(), "duration {duration}");
    }
    for force in [f64::NAN, f64::INFINITY, -1.0, 1e300, MAX_FORCE + 1.0] {
        assert!(cell.controller.law.command_force(force, 2.0).is_err(), "force {force}");
    }
    for z in [f64::NAN, -1e300, -0.06, 0.07, 1e300, f64::NEG_INFINITY] {
        assert!(cell.controller.law.command_deformation(z, 2.0).is_err(), "deformation {z}");
    }
    for (low, high, frequency, periods) in
        [(0.0, 0.01, 1e-300, 3), (0.0, 0.01, 1e300, 3), (0.0, 0.01, 1.0, u32::MAX), (-1e300, 0.01, 1.0, 3)]
    {
        assert!(cell.controller.law.command_pushes(low, high, frequency, periods).is_err(), "{frequency} {periods}");
    }
    assert_stays_put(&mut cell, "refused commands");
}

#[test]
fn implausible_models_are_refused_and_a_command_through_them_does_not_crush() {
    // Class 8: a model placing the surface 5 cm too low turned a 50 N command into 302 N; a contact
    // position of 1e300 made the hand jump.
    let mut cell = pressing(22);
    let surface = cell.lockstep.sim.surface.as_ref().unwrap().config().point;
    let sponge = softcontact_sim::sponge();
    let n = Vector3::new(0.0, 0.0, -1.0);
    for (model, at) in [
        (sponge.clone(), surface + 0.05 * n),
        (sponge.clone(), surface - 0.05 * n),
        (sponge.clone(), Vector3::new(0.0, 0.0, 1e300)),
        (sponge.clone(), Vector3::new(f64::NAN, 0.0, 0.0)),
        (ContactModel::general(2e4, 0.0, Exponents { a: 9.0, b: 0.0, c: 1.0 }).unwrap(), surface),
    ] {
        assert!(cell.controller.law.adopt_estimate(model, &at, Some(0.5)).is_err(), "{at:?}");
    }
    assert_stays_put(&mut cell, "refused models");
    cell.controller.law.command_force(50.0, 1.0).unwrap();
    run(&mut cell, 2000);
    let f = cell.lockstep.sim.contact().normal_force;
    assert!((f - 50.0).abs() < 5.0, "50 N commanded, {f:.1} N reached");
}

#[test]
fn a_model_far_too_soft_and_misplaced_backs_off_below_max_force() {
    // Class 8: the back-off used the model's surface; with a misplaced one it left 277 N (max 250 N).
    let mut cell = pressing(23);
    let surface = cell.lockstep.sim.surface.as_ref().unwrap().config().point;
    let too_soft = ContactModel::new(Kind::AzadFeatherstone, 15_000.0, 0.0).unwrap();
    // Within the plausible offset, but the wrong way: the model thinks the hand is 9 mm shallower.
    cell.controller.law.adopt_estimate(too_soft, &(surface + Vector3::new(0.0, 0.0, -0.009)), None).unwrap();
    cell.controller.law.command_force(MAX_FORCE * 0.8, 2.0).unwrap();
    let mut limited = false;
    for k in 0..4000 {
        limited |= cell.cycle().unwrap().is_some_and(|t| t.controller.force_limited);
        if let Some(v) = violation(&cell.lockstep.sim) {
            panic!("cycle {k}: {v}");
        }
    }
    let f = cell.lockstep.sim.contact().normal_force;
    assert!(limited, "the force limit was reached");
    assert!(f <= MAX_FORCE, "after the back-off {f:.1} N, max {MAX_FORCE} N");
}

#[test]
fn a_restarted_krc_session_makes_the_controller_approach_again() {
    // Class 2: a restarted arm was driven 63 mm into the sponge by a controller that kept its old
    // contact state. The KRC restarts (its arm back above the sponge); the driver sees a new session.
    let mut cell = pressing(24);
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), 25);
    config.sensor = softcontact_sim::FtSensorConfig::gamma();
    cell.lockstep.sim = Simulator::new(config).unwrap();
    cell.lockstep.driver.begin_session();
    let mut deepest: f64 = 0.0;
    for k in 0..8000 {
        cell.cycle().unwrap();
        if let Some(v) = violation(&cell.lockstep.sim) {
            panic!("cycle {k}: {v}");
        }
        deepest = deepest.max(cell.lockstep.sim.contact().deformation);
    }
    // A gentle approach stops within a few millimetres of the 1 N onset.
    assert!(deepest < 5e-3, "the hand went {:.1} mm into the sponge", deepest * 1e3);
    assert!(cell.controller.law.contact_model().stiffness > 0.0);
}

/// One random or extreme value: a third of the time an extreme.
fn value(rng: &mut SmallRng, typical: std::ops::Range<f64>) -> f64 {
    const EXTREMES: [f64; 12] = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e300,
        -1e300,
        1e154,
        0.0,
        -0.0,
        1e-300,
        -1.0,
        f64::MAX,
        f64::MIN_POSITIVE,
    ];
    if rng.random_bool(1.0 / 3.0) { EXTREMES[rng.random_range(0..EXTREMES.len())] } else { rng.random_range(typical) }
}

#[test]
fn fuzzed_commands_and_models_from_contact_never_break_the_limits() {
    let cases: usize = std::env::var("SOFTCONTACT_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(1000);
    let mut rng = SmallRng::seed_from_u64(0xF022);
    let mut cell = pressing(26);
    let surface = cell.lockstep.sim.surface.as_ref().unwrap().config().point;
    let (mut accepted, mut refused) = (0, 0);
    let mut recent = std::collections::VecDeque::new();
    for case in 0..cases {
        let result = match rng.random_range(0..4) {
            0 => cell.controller.law.command_force(value(&mut rng, -50.0..400.0), value(&mut rng, 0.0..5.0)),
            1 => cell.controller.law.command_deformation(value(&mut rng, -0.08..0.08), value(&mut rng, 0.0..5.0)),
            2 => cell.controller.law.command_pushes(
                value(&mut rng, -0.01..0.05),
                value(&mut rng, -0.01..0.05),
                value(&mut rng, 0.0..20.0),
                rng.random_range(0..5),
            ),
            _ => {
                let exponents = Exponents {
                    a: value(&mut rng, 0.5..3.0),
                    b: value(&mut rng, 0.0..2.0),
                    c: value(&mut rng, 0.5..2.0),
                };
                let offset = Vector3::new(0.0, 0.0, value(&mut rng, -0.02..0.02));
                let retarget = rng.random_bool(0.5).then(|| value(&mut rng, 0.0..2.0));
                match ContactModel::general(value(&mut rng, 1e2..1e6), value(&mut rng, 0.0..1e4), exponents) {
                    Ok(model) => cell.controller.law.adopt_estimate(model, &(surface + offset), retarget),
                    Err(_) => Ok(()), // refused by the model itself, never reaches the controller
                }
            }
        };
        if result.is_ok() {
            accepted += 1
        } else {
            refused += 1
        }
        // Each input is followed by 50 ms of control, invariants checked every cycle.
        for k in 0..50 {
            let tick = cell.cycle().unwrap();
            if let Some(v) = violation(&cell.lockstep.sim) {
                let state = tick.map(|t| t.controller);
                panic!("case {case} ({result:?}), cycle {k}: {v}\nbefore: {recent:#?}\nnow: {state:?}");
            }
        }
        recent.push_back(format!("case {case}: {result:?}; then {:.1} N", cell.lockstep.sim.contact().normal_force));
        if recent.len() > 4 {
            recent.pop_front();
        }
    }
    eprintln!("{cases} fuzz cases: {accepted} accepted, {refused} refused, no violation");
    assert!(accepted > cases / 20 && refused > cases / 5, "{accepted} accepted, {refused} refused");
}

#[test]
fn a_new_session_while_pressing_places_the_surface_by_the_force_read() {
    // Adversarial finding: after a restart while pushing 200 N, the onset fired at the deformed
    // position, taken for the surface, and a 10 N command then held 220 N.
    let mut cell = pressing(27);
    cell.controller.law.command_force(200.0, 2.0).unwrap();
    run(&mut cell, 2500);
    cell.lockstep.driver.begin_session();
    let moved = run(&mut cell, 1000);
    assert!(moved < 5e-3, "the new session moved the hand {:.1} mm", moved * 1e3);
    cell.controller.law.command_force(10.0, 2.0).unwrap();
    run(&mut cell, 3000);
    let f = cell.lockstep.sim.contact().normal_force;
    assert!((f - 10.0).abs() < 5.0, "10 N commanded after the new session, {f:.1} N held");
}

/// One cycle with the controller stalled: the KRC's measurement is answered by the driver alone.
fn stalled_cycle(cell: &mut Cell) {
    let m = cell.lockstep.sim.measurement().encode();
    let (reply, _) = cell.lockstep.driver.handle(&m).unwrap();
    cell.lockstep.sim.command(&reply);
    cell.lockstep.sim.step_cycle().unwrap();
}

#[test]
fn a_controller_stalled_while_pressing_leaves_the_hand_in_place() {
    // Adversarial finding: the controller stopped for 1.5 s while pushing 200 N; the hold faded the
    // torque that balanced the sponge and the sponge threw the hand back 27 mm.
    let mut cell = pressing(28);
    cell.controller.law.command_force(200.0, 2.0).unwrap();
    run(&mut cell, 2500);
    let f0 = cell.lockstep.sim.contact().normal_force;
    let start = cell.lockstep.sim.tool_pose().translation.vector;
    let (mut moved, mut f_min, mut f_max): (f64, f64, f64) = (0.0, f0, f0);
    for k in 0..3000 {
        stalled_cycle(&mut cell);
        if let Some(v) = violation(&cell.lockstep.sim) {
            panic!("stalled cycle {k}: {v}");
        }
        moved = moved.max((cell.lockstep.sim.tool_pose().translation.vector - start).norm());
        let f = cell.lockstep.sim.contact().normal_force;
        (f_min, f_max) = (f_min.min(f), f_max.max(f));
    }
    eprintln!("stall at {f0:.1} N: hand moved {:.2} mm, force {f_min:.1}..{f_max:.1} N", moved * 1e3);
    assert!(moved < 3e-3, "the hand moved {:.1} mm in the stall", moved * 1e3);
    assert!(f_max <= f0 + 10.0 && f_min >= 0.8 * f0, "force {f_min:.1}..{f_max:.1} N from {f0:.1} N");
}

#[test]
fn a_surface_vanishing_in_a_stall_moves_no_joint_farther_than_the_holds_preload() {
    // The other side of the stiff hold: what it carries on moves the arm should the surface give way.
    let mut cell = pressing(29);
    cell.controller.law.command_force(200.0, 2.0).unwrap();
    run(&mut cell, 2500);
    // The watchdog holds after 5 cycles without a command; then the surface goes.
    for _ in 0..6 {
        stalled_cycle(&mut cell);
    }
    let held = *cell.lockstep.sim.q();
    cell.lockstep.sim.surface = None;
    let preload = softcontact_nodes::lwr_driver::Params::default().hold_max_preload;
    let mut farthest: f64 = 0.0;
    for k in 0..3000 {
        stalled_cycle(&mut cell);
        if let Some(v) = violation(&cell.lockstep.sim) {
            panic!("stalled cycle {k}: {v}");
        }
        farthest = cell.lockstep.sim.q().iter().zip(&held).fold(farthest, |m, (q, h)| m.max((q - h).abs()));
    }
    let last: Vec<f64> = cell.lockstep.sim.q().iter().zip(&held).map(|(q, h)| q - h).collect();
    eprintln!(
        "surface gone in a stall: farthest joint {farthest:.4} rad from the held position, at the end {last:.4?}"
    );
    // The spring's set point is at most `preload` away: the arm settles there. On the way the rest of the
    // torque, beyond what the preload carries, still fades.
    assert!(last.iter().all(|d| d.abs() <= 1.02 * preload), "settled {last:.4?}, the preload is {preload} rad");
    assert!(farthest <= 1.5 * preload, "a joint moved {farthest:.4} rad, the preload is {preload} rad");
}

#[test]
fn a_tare_while_pressing_is_refused_and_the_force_read_stays_true() {
    // A tare in contact would zero the contact force: the controller would then push on, blind.
    let mut cell = pressing(30);
    let err = cell.tare().expect_err("tare in contact");
    assert!(err.to_string().contains("tare refused"), "{err}");
    let f_read = (0..100).filter_map(|_| cell.cycle().unwrap()).last().unwrap().controller.f;
    let f_true = cell.lockstep.sim.contact().normal_force;
    assert!((f_read - f_true).abs() < 3.0, "read {f_read:.1} N, true {f_true:.1} N");
}

#[test]
fn an_approach_that_finds_no_surface_stops_after_max_approach() {
    // A missing object or a wrong `normal` sent the approach on until a joint limit.
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), 31);
    config.sensor = softcontact_sim::FtSensorConfig::gamma();
    config.surface = None;
    let mut controller_config = ControllerConfig::lwr4(MAX_FORCE, 0.06);
    controller_config.max_approach = 0.03;
    let controller = DeformationController::new(controller_config, softcontact_sim::sponge()).unwrap();
    let estimator = ContactEstimatorNode::new(EstimatorConfig::default()).unwrap();
    let mut cell = Cell::new(config, controller, estimator).unwrap();
    cell.start(2000).unwrap();
    let start = cell.lockstep.sim.tool_pose().translation.vector;
    // 8 s at 1 cm/s would be 8 cm.
    run(&mut cell, 8000);
    let travelled = (cell.lockstep.sim.tool_pose().translation.vector - start).norm();
    assert!(cell.controller.law.approach_exhausted());
    assert!(travelled < 0.031, "the approach went {:.1} mm, max_approach 30 mm", travelled * 1e3);
    let still = run(&mut cell, 1000);
    assert!(still < 1e-3, "then it holds: {:.2} mm in 1 s", still * 1e3);
}

/// How many numbers a parameter tree holds.
fn numbers(v: &serde_yaml_ng::Value) -> usize {
    use serde_yaml_ng::Value;
    match v {
        Value::Number(_) => 1,
        Value::Sequence(s) => s.iter().map(numbers).sum(),
        Value::Mapping(m) => m.values().map(numbers).sum(),
        _ => 0,
    }
}

/// Replaces the `k`-th number of a parameter tree by `new(old)`; false once past the end.
fn replace_number(
    v: &mut serde_yaml_ng::Value,
    k: &mut usize,
    new: &mut impl FnMut(&serde_yaml_ng::Number) -> serde_yaml_ng::Value,
) -> bool {
    use serde_yaml_ng::Value;
    match v {
        Value::Number(n) if *k == 0 => {
            *v = new(n);
            true
        }
        Value::Number(_) => {
            *k -= 1;
            false
        }
        Value::Sequence(s) => s.iter_mut().any(|x| replace_number(x, k, new)),
        Value::Mapping(m) => m.values_mut().any(|x| replace_number(x, k, new)),
        _ => false,
    }
}

/// `params` with `count` of its numbers replaced by random or extreme ones; `None` if that no longer
/// deserializes (a negative or fractional count, say), which refuses it as surely as `validate`.
fn fuzzed<P: serde::Serialize + serde::de::DeserializeOwned>(
    params: &P,
    count: usize,
    rng: &mut SmallRng,
) -> Option<P> {
    let mut tree = serde_yaml_ng::to_value(params).unwrap();
    for _ in 0..count {
        let mut k = rng.random_range(0..numbers(&tree));
        replace_number(&mut tree, &mut k, &mut |old| {
            if old.is_f64() {
                let x = old.as_f64().unwrap();
                // A user's edit: half to twice the default (or an extreme, a third of the time).
                let typical = if x == 0.0 { -1.0..1.0 } else { (x.abs() * 0.5)..(x.abs() * 2.0) };
                serde_yaml_ng::Value::from(value(rng, typical))
            } else {
                const COUNTS: [i64; 7] = [0, 1, 2, 7, 1000, u32::MAX as i64, i64::MAX];
                serde_yaml_ng::Value::from(if rng.random_bool(0.5) { COUNTS[rng.random_range(0..7)] } else { -1 })
            }
        });
    }
    serde_yaml_ng::from_value(tree).ok()
}

#[test]
fn fuzzed_node_parameters_are_refused_or_keep_the_arm_within_its_limits() {
    // Every parameter a user can set reaches the arm through the controller's and driver's configs:
    // a set the nodes accept must keep the limits through approach, contact, a force and a
    // deformation command (SOFTCONTACT_FUZZ_CASES / 200 accepted sets run, at least 6).
    use softcontact_nodes::deformation_controller::Params as ControllerParams;
    use softcontact_nodes::lwr_driver::{LwrDriver, Params as DriverParams};
    use softcontact_nodes::runtime::params::NodeParams;
    let cases: usize = std::env::var("SOFTCONTACT_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(1000);
    let wanted = (cases / 200).max(6);
    let mut rng = SmallRng::seed_from_u64(0x9A7A);
    let (mut accepted, mut refused) = (0, 0);
    for set in 0..wanted * 50 {
        if accepted == wanted {
            break;
        }
        let n = rng.random_range(1..3);
        let controller = fuzzed(&ControllerParams::default(), n, &mut rng).filter(|p| p.validate().is_ok());
        let n = rng.random_range(0..3);
        let driver = fuzzed(&DriverParams::default(), n, &mut rng).filter(|p| p.validate().is_ok());
        let (Some(cp), Some(dp)) = (controller, driver) else {
            refused += 1;
            continue;
        };
        accepted += 1;
        let mut config = SimConfig::above_surface(softcontact_sim::sponge(), 100 + set as u64);
        config.sensor = softcontact_sim::FtSensorConfig::gamma();
        let controller = DeformationController::new(cp.controller_config(), cp.initial_model.clone()).unwrap();
        let estimator = ContactEstimatorNode::new(EstimatorConfig::default()).unwrap();
        let mut cell = Cell::new(config, controller, estimator).unwrap();
        cell.lockstep.driver = LwrDriver::new(dp.clone());
        let bound = 1.2 * cp.force_limit;
        let check = |cell: &mut Cell, cycles: usize, what: &str| {
            for k in 0..cycles {
                cell.cycle().unwrap();
                if let Some(v) = violation_within(&cell.lockstep.sim, bound) {
                    panic!("set {set} ({what}), cycle {k}: {v}\ncontroller {cp:?}\ndriver {dp:?}");
                }
            }
        };
        check(&mut cell, 6000, "approach");
        let force = cp.max_force.min(100.0) * 0.8;
        let forced = cell.controller.law.command_force(force, 1.0);
        check(&mut cell, 2000, &format!("force {force} N: {forced:?}"));
        let pressed = cell.controller.law.command_deformation(0.01, 1.0);
        check(&mut cell, 1500, &format!("deformation 10 mm: {pressed:?}"));
    }
    eprintln!("fuzzed parameter sets: {accepted} accepted and run, {refused} refused, no violation");
    assert!(accepted == wanted && refused > 0, "{accepted} accepted, {refused} refused");
}

#[test]
fn a_deformation_command_right_after_a_back_off_is_still_guarded() {
    // Found by the 10 000-case fuzz: the guard waited 0.2 s from the start of the newest plan, not of
    // the back-off, so a deep deformation command just after a back-off pushed on, unguarded, to 301 N.
    let mut cell = pressing(32);
    let surface = cell.lockstep.sim.surface.as_ref().unwrap().config().point;
    // A model far too soft, within the plausible offset: a force command overshoots into the guard.
    let too_soft = ContactModel::new(Kind::AzadFeatherstone, 18_000.0, 0.0).unwrap();
    cell.controller.law.adopt_estimate(too_soft, &surface, None).unwrap();
    cell.controller.law.command_force(MAX_FORCE * 0.95, 0.5).unwrap();
    let mut limited = false;
    for _ in 0..1000 {
        limited = cell.cycle().unwrap().is_some_and(|t| t.controller.force_limited);
        if limited {
            break;
        }
    }
    assert!(limited, "the guard fired");
    cell.controller.law.command_deformation(0.058, 0.4).unwrap();
    let mut peak: f64 = 0.0;
    for k in 0..2000 {
        cell.cycle().unwrap();
        peak = peak.max(cell.lockstep.sim.contact().normal_force);
        if let Some(v) = violation(&cell.lockstep.sim) {
            panic!("cycle {k}: {v}");
        }
    }
    eprintln!("deformation command after a back-off: peak {peak:.1} N");
}

/// The KRC commanding, the hand above the sponge, and whatever writes the driver's commands (a stranger,
/// a controller gone wrong) pushing one joint with `push` N·m beyond gravity, within the torque limits,
/// until 0.5 s after the driver's fault (at most 6 s); the fault the driver held for.
fn pushed(joint: usize, push: f64) -> Option<softcontact_nodes::lwr_driver::Fault> {
    use softcontact_nodes::lwr_driver::{LwrDriver, Params as DriverParams};
    let mut sim = Simulator::new(SimConfig::above_surface(softcontact_sim::sponge(), 3)).unwrap();
    let mut driver = LwrDriver::new(DriverParams::default());
    let model = lwr4::model();
    let mut data = model.data();
    let limit = model.joints[joint].limits.effort;
    let mut held_for = 0;
    for k in 0..6000 {
        if held_for > 500 {
            break;
        }
        held_for += usize::from(driver.fault().is_some());
        let measured = driver.measure(&sim.measurement().encode()).unwrap();
        let mut tau: Vec<f64> = model.gravity_torques(&mut data, &measured.output.q).iter().copied().collect();
        tau[joint] = (tau[joint] + push).clamp(-limit, limit);
        driver.set_command(&tau).unwrap();
        let (reply, _) = driver.answer(measured);
        sim.command(&reply);
        sim.step_cycle().unwrap();
        if let Some(v) = violation_within(&sim, f64::INFINITY) {
            panic!("joint {} pushed {push} N·m, cycle {k}: {v}", joint + 1);
        }
    }
    driver.fault()
}

#[test]
fn torques_that_drive_a_joint_to_its_limits_are_stopped_before_them() {
    // Adversary, separate layout: a stranger's +8 N·m on joint 5 carried it past its position limit;
    // 176 N·m on joint 1 swung it 114° and took joint 3 past its limit. Whoever commands, within the
    // torque limits, every joint stays within its position and velocity limits.
    let model = lwr4::model();
    for joint in 0..7 {
        let limit = model.joints[joint].limits.effort;
        for push in [0.1 * limit, -0.1 * limit, limit, -limit] {
            let fault = pushed(joint, push);
            eprintln!("joint {} pushed {push:.1} N·m: {fault:?}", joint + 1);
            assert!(fault.is_some(), "joint {} pushed {push:.1} N·m: no fault, yet a push of its own", joint + 1);
        }
    }
}
