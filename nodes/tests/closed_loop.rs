//! The closed loop in-process, in lockstep with the simulator: the very driver and F/T node code
//! exchanges real FRI and RDT bytes with the simulated cell, the deformation controller closes the loop,
//! and the contact model and surface position come from the estimator node ([`softcontact_simcell::cell`]). Force commands
//! on the simulated sponge must be reached within 5 %.

use softcontact_contact::Kind;
use softcontact_nodes::contact_estimator::{ContactEstimatorNode, EstimatorConfig};
use softcontact_nodes::deformation_controller::{ControllerConfig, ControllerState, DeformationController};
use softcontact_sim::SimConfig;
use softcontact_simcell::cell::Cell;
use softcontact_wire::fri::InterfaceState;

struct Loop(Cell);

impl Loop {
    fn new(sim: SimConfig, controller: DeformationController) -> Self {
        let estimator = ContactEstimatorNode::new(EstimatorConfig::default()).unwrap();
        Loop(Cell::new(sim, controller, estimator).unwrap())
    }

    /// One cycle; the controller's state once commanding.
    fn cycle(&mut self) -> Option<ControllerState> {
        self.0.cycle().unwrap().map(|t| t.controller)
    }
}

#[test]
fn force_commands_on_the_sponge_are_reached_within_five_percent() {
    let sponge = softcontact_sim::sponge();
    let mut config = SimConfig::above_surface(sponge.clone(), 11);
    config.sensor = softcontact_sim::FtSensorConfig::gamma();
    // The controller starts with a rough guess of the surface (half the stiffness): it learns it.
    let guess = softcontact_contact::ContactModel::new(Kind::AzadFeatherstone, 12_000.0, 0.0).unwrap();
    let mut l = Loop::new(config, DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), guess).unwrap());
    // Approach until contact (the hand starts 4 cm above the sponge and descends at 1 cm/s).
    let mut cycles = 0;
    while !l.cycle().is_some_and(|s| s.in_contact) {
        cycles += 1;
        assert!(cycles < 10_000, "no contact after 10 s");
    }
    // Identification as the force-control paper does it, with pushes at 1 Hz (the damping term needs motion to be
    // seen), using the guessed model; the estimator node watches. 12 s fill the 1200-sample window.
    for _ in 0..12 {
        for force in [100.0, 30.0] {
            l.0.controller.law.command_force(force, 0.5).unwrap();
            for _ in 0..500 {
                l.cycle().unwrap();
            }
        }
    }
    let learned = l.0.estimator.refit().unwrap();
    let surface_top = l.0.lockstep.sim.surface.as_ref().unwrap().config().point.z;
    eprintln!(
        "learned: {:?} k {:.0} λ {:.0}, surface {:.2} mm from the onset, at z = {:.4} m (truth {surface_top:.4}); window {:.0} %",
        learned.model.kind,
        learned.model.stiffness,
        learned.model.damping,
        learned.offset * 1e3,
        learned.contact_position.z,
        learned.window_fill * 100.0
    );
    assert_eq!(learned.estimate.selected, Kind::AzadFeatherstone, "the sponge's kind is chosen");
    assert!(
        (learned.model.stiffness / sponge.stiffness - 1.0).abs() < 0.1,
        "k {} vs {}",
        learned.model.stiffness,
        sponge.stiffness
    );
    assert!((learned.contact_position.z - surface_top).abs() < 1e-3, "surface placed within 1 mm");
    l.0.controller.law.set_contact_model(learned.model.clone(), learned.offset).unwrap();
    // The force-control paper's control experiment, shortened: 2 s quintic moves, force read at the end of each move.
    let mut errors = Vec::new();
    for ratio in [0.5, 0.3, 0.7, 0.4, 0.6] {
        let command = ratio * 280.0;
        l.0.controller.law.command_force(command, 2.0).unwrap();
        let mut at_end = Vec::new();
        for k in 0..2000 {
            let s = l.cycle().unwrap();
            assert!(!s.contact_lost);
            if k >= 1950 {
                at_end.push(s.f);
            }
        }
        let f = at_end.iter().sum::<f64>() / at_end.len() as f64;
        errors.push(((f - command) / command).abs());
        eprintln!("command {command:.0} N: reached {f:.1} N ({:+.2} %)", (f - command) / command * 100.0);
    }
    assert!(errors.iter().all(|e| *e < 0.05), "relative errors {errors:?}");
    assert_eq!(l.0.lockstep.sim.krc.state(), InterfaceState::Command);
    assert_eq!(l.0.lockstep.driver.counters.overspeed_cycles, 0);
}

#[test]
fn losing_the_surface_stops_the_push() {
    let mut config = SimConfig::above_surface(softcontact_sim::dice(), 12);
    config.sensor = softcontact_sim::FtSensorConfig::ideal();
    let controller = DeformationController::new(ControllerConfig::lwr4(120.0, 0.08), softcontact_sim::dice()).unwrap();
    let mut l = Loop::new(config, controller);
    while !l.cycle().is_some_and(|s| s.in_contact) {}
    assert!(l.0.controller.law.command_force(500.0, 2.0).is_err(), "beyond the surface's force limit");
    l.0.controller.law.command_force(60.0, 2.0).unwrap();
    for _ in 0..2500 {
        l.cycle();
    }
    // The dice is taken away.
    l.0.lockstep.sim.surface = None;
    let mut lost = None;
    for k in 0..1000 {
        let s = l.cycle().unwrap();
        if s.contact_lost && lost.is_none() {
            lost = Some(k);
        }
    }
    assert!(lost.is_some_and(|k| k < 50), "contact loss noticed: {lost:?}");
    let tool = l.0.lockstep.sim.tool_pose().translation.vector;
    let drop = l.0.lockstep.sim.contact().deformation;
    assert_eq!(drop, 0.0);
    assert!(
        l.0.lockstep.sim.dq().iter().all(|v| v.abs() < 0.05),
        "holding, not falling: {:?} at {tool}",
        l.0.lockstep.sim.dq()
    );
}

#[test]
fn a_push_from_a_light_touch_on_a_relaxing_surface_is_not_a_lost_contact() {
    // The lab sponge relaxes: held at the onset, its force sinks below the contact-lost threshold. A
    // force command from there must push, not stop (the model expects no force at that depth yet).
    let mut config = SimConfig::above_surface(softcontact_sim::lab_sponge(), 13);
    config.sensor = softcontact_sim::FtSensorConfig::ideal();
    let controller =
        DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), softcontact_sim::sponge()).unwrap();
    let mut l = Loop::new(config, controller);
    while !l.cycle().is_some_and(|s| s.in_contact) {}
    let mut held = 0.0;
    for _ in 0..1000 {
        held = l.cycle().unwrap().f;
    }
    assert!(held < 0.5, "the touch relaxed below the threshold: {held} N");
    l.0.controller.law.command_force(100.0, 1.0).unwrap();
    let mut last = None;
    for _ in 0..1500 {
        let s = l.cycle().unwrap();
        assert!(!s.contact_lost, "taken for a lost contact at f = {} N, z = {} m", s.f, s.z);
        last = Some(s);
    }
    let f = last.unwrap().f;
    assert!((f - 100.0).abs() < 10.0, "pushed to {f} N");
}

#[test]
fn a_model_far_too_soft_cannot_crush_the_surface() {
    // The controller believes the dice is twice as soft as it is: a 100 N command would press it to
    // about 185 N. Past the force limit (1.2 × 120 N) the controller backs off and waits.
    let mut config = SimConfig::above_surface(softcontact_sim::dice(), 14);
    config.sensor = softcontact_sim::FtSensorConfig::gamma();
    let too_soft = softcontact_contact::ContactModel::new(Kind::KelvinVoigt, 1_000.0, 0.0).unwrap();
    let config_limits = ControllerConfig::lwr4(120.0, 0.1);
    let force_limit = config_limits.limits.force_limit;
    let mut l = Loop::new(config, DeformationController::new(config_limits, too_soft).unwrap());
    while !l.cycle().is_some_and(|s| s.in_contact) {}
    l.0.controller.law.command_force(100.0, 2.0).unwrap();
    let (mut peak, mut limited_at) = (0.0f64, None);
    for k in 0..3000 {
        let s = l.cycle().unwrap();
        peak = peak.max(s.f);
        if s.force_limited && limited_at.is_none() {
            limited_at = Some(k);
            assert_eq!(s.f_cmd, 0.0, "the force command is dropped");
        }
        if let Some(at) = limited_at {
            assert!(s.force_limited, "stays backed off until a new command");
            if k > at + 500 {
                assert!(s.f <= 120.0, "backed off to at most max_force: {} N, {} ms after the limit", s.f, k - at);
            }
        }
    }
    assert!(limited_at.is_some(), "the force limit was passed without a reaction (peak {peak:.1} N)");
    assert!(peak < force_limit + 10.0, "peak {peak:.1} N: the back-off came late (limit {force_limit} N)");
    assert!(
        l.0.lockstep.sim.dq().iter().all(|v| v.abs() < 0.05),
        "still after backing off: {:?}",
        l.0.lockstep.sim.dq()
    );
    // A new command is taken (within the limit of this wrong model's deformations).
    l.0.controller.law.command_force(40.0, 1.0).unwrap();
    assert!(!l.cycle().unwrap().force_limited);
}

#[test]
fn a_controller_that_stalls_while_pushing_does_not_kick_the_hand_back() {
    // Pushing the sponge at 150 N, the controller misses 20 cycles (a scheduling hiccup): the driver's
    // watchdog holds after 5, and the hand must stay where it is, not be thrown back by the surface.
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), 12);
    config.sensor = softcontact_sim::FtSensorConfig::gamma();
    let model = softcontact_contact::ContactModel::new(Kind::AzadFeatherstone, 25_044.0, 1_100.0).unwrap();
    let mut l = Loop::new(config, DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), model).unwrap());
    while !l.cycle().is_some_and(|s| s.in_contact) {}
    l.0.controller.law.command_force(150.0, 2.0).unwrap();
    for _ in 0..3000 {
        l.cycle().unwrap();
    }
    let before = l.0.lockstep.sim.contact().normal_force;
    let cell = &mut l.0;
    let mut z = Vec::new();
    let mut held = 0;
    for _ in 0..20 {
        // The driver and the arm run on; nobody sets a new command.
        let (reply, out) = cell.lockstep.driver.handle(&cell.lockstep.sim.measurement().encode()).unwrap();
        cell.lockstep.sim.command(&reply);
        cell.lockstep.sim.step_cycle().unwrap();
        held += usize::from(out.holding);
        z.push(cell.lockstep.sim.contact().deformation);
    }
    assert!(held >= 14, "the watchdog held ({held} cycles)");
    let moved = z.iter().fold(0.0f64, |m, v| m.max((v - z[0]).abs()));
    let after = l.0.lockstep.sim.contact().normal_force;
    assert!(moved < 2e-4, "the hand moved {:.3} mm during the stall", moved * 1e3);
    assert!((after - before).abs() < 0.05 * before, "force {before:.1} N before the stall, {after:.1} N after");
    for _ in 0..500 {
        l.cycle().unwrap();
    }
    assert!((l.0.lockstep.sim.contact().normal_force - 150.0).abs() < 7.5, "back at the command after the stall");
}

/// Read → update → write in one process: after start-up (the KRC commands and the F/T node has tared),
/// every FRI measurement is answered with the torque the controller computed for that very measurement —
/// no held or older command, through approach, contact and force commands — and the torque the KRC
/// receives is that one, less the KRC's own gravity.
#[test]
fn every_measurement_is_answered_with_the_torque_computed_for_it() {
    let config = SimConfig::above_surface(softcontact_sim::sponge(), 5);
    let controller =
        DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), softcontact_sim::sponge()).unwrap();
    let mut l = Loop::new(config, controller);
    l.0.start(5000).unwrap();
    let model = softcontact_dynamics::lwr4::model();
    let mut data = model.data();
    let stale_at_start = l.0.lockstep.driver.counters.stale_cycles;
    let (mut answered, mut commands) = (0, 0);
    for i in 0..8000 {
        if i == 5000 {
            l.0.controller.law.command_force(120.0, 1.0).unwrap();
            commands += 1;
        }
        let tick = l.0.cycle().unwrap().expect("the KRC commands");
        let tau = tick.torque.unwrap_or_else(|| panic!("cycle {i}: no torque ({:?})", tick.refused));
        assert!(!tick.driver.holding, "cycle {i}: the driver held");
        // What the KRC received: this tick's torque (within the joint limits) less the KRC's own gravity.
        let received = l.0.lockstep.sim.krc.last_command().expect("a reply").add_jnt_trq;
        let gravity = model.gravity_torques(&mut data, &tick.driver.q);
        for j in 0..7 {
            let limit = model.joints[j].limits.effort;
            let expected = tau[j].clamp(-limit, limit) - gravity[j];
            assert!(
                (received[j] as f64 - expected).abs() < 1e-4,
                "cycle {i}, joint {}: the KRC received {} N·m, this tick's torque less gravity is {expected} N·m",
                j + 1,
                received[j]
            );
        }
        answered += 1;
    }
    assert_eq!(l.0.lockstep.driver.counters.stale_cycles, stale_at_start, "cycles answered with a held command");
    assert!(answered == 8000 && commands == 1);
    assert!(l.0.lockstep.sim.contact().normal_force > 60.0, "the force command was carried out");
}

#[test]
fn a_force_is_reached_and_held_at_every_fri_cycle_the_krc_offers_from_1_to_10_ms() {
    for ms in [1u32, 2, 5, 10] {
        let cycle = f64::from(ms) * 1e-3;
        let mut config = SimConfig::above_surface(softcontact_sim::dice(), 12);
        config.sensor = softcontact_sim::FtSensorConfig::ideal();
        config.cycle = cycle;
        config.krc.cycle = cycle;
        let controller =
            DeformationController::new(ControllerConfig::lwr4(120.0, 0.08), softcontact_sim::dice()).unwrap();
        let mut l = Loop::new(config, controller);
        let per_second = 1000 / ms as usize;
        let mut cycles = 0;
        while !l.cycle().is_some_and(|s| s.in_contact) {
            cycles += 1;
            assert!(cycles < 20 * per_second, "{ms} ms: no contact after 20 s");
        }
        l.0.controller.law.command_force(60.0, 2.0).unwrap();
        let (mut last, mut peak) = (Vec::new(), 0.0f64);
        for k in 0..4 * per_second {
            let s = l.cycle().unwrap();
            assert!(!s.contact_lost, "{ms} ms");
            peak = peak.max(s.f);
            if k >= 15 * per_second / 4 {
                last.push(s.f);
            }
        }
        let f = last.iter().sum::<f64>() / last.len() as f64;
        eprintln!("FRI cycle {ms} ms: 60 N held at {f:.2} N, peak {peak:.2} N");
        assert!((l.0.lockstep.driver.sample_time() - cycle).abs() < 1e-6, "the driver runs the KRC's cycle");
        assert!((f - 60.0).abs() < 0.05 * 60.0 && peak < 1.05 * 60.0, "{ms} ms: {f:.2} N, peak {peak:.2} N");
        assert_eq!(l.0.lockstep.sim.krc.state(), InterfaceState::Command);
    }
    // A KRL program that opens FRI at 20 ms gets no torque: the hand stays where it is.
    let mut config = SimConfig::above_surface(softcontact_sim::dice(), 12);
    (config.cycle, config.krc.cycle) = (0.020, 0.020);
    let controller = DeformationController::new(ControllerConfig::lwr4(120.0, 0.08), softcontact_sim::dice()).unwrap();
    let mut l = Loop::new(config, controller);
    let start = l.0.lockstep.sim.q()[1];
    for _ in 0..250 {
        assert!(l.cycle().is_none(), "no controller tick at 20 ms");
    }
    assert!((l.0.lockstep.sim.q()[1] - start).abs() < 1e-3, "joint 2 moved {} rad", l.0.lockstep.sim.q()[1] - start);
    let measured = l.0.lockstep.driver.measure(&l.0.lockstep.sim.measurement().encode()).unwrap();
    let waiting = measured.output.waiting.map(|w| w.to_string()).unwrap_or_default();
    assert!(waiting.contains("FRI cycle 20 ms"), "{waiting}");
}
