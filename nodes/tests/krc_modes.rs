//! The KRC's modes in the lockstep cell: torque reaches the arm only in joint impedance with the KRL
//! program's handshake done (docs/safety.md). A KRC in position control, drives off or a strategy
//! switched mid-press gets no torque, the arm stays put, the controller integrates nothing, and it
//! approaches again once torque mode is back.

// `!(x <= limit)` on purpose: a NaN is a violation too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use softcontact_dynamics::lwr4;
use softcontact_nodes::contact_estimator::{ContactEstimatorNode, EstimatorConfig};
use softcontact_nodes::deformation_controller::{ControllerConfig, DeformationController};
use softcontact_nodes::lwr_driver::Waiting;
use softcontact_sim::{KrlProgram, STRATEGY_JOINT_IMPEDANCE, STRATEGY_POSITION, SimConfig, Simulator};
use softcontact_simcell::cell::Cell;
use softcontact_wire::fri::{ControlMode, InterfaceState};

const MAX_FORCE: f64 = 250.0;

fn cell(program: KrlProgram, seed: u64) -> Cell {
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), seed);
    config.sensor = softcontact_sim::FtSensorConfig::gamma();
    config.krc.program = program;
    let controller =
        DeformationController::new(ControllerConfig::lwr4(MAX_FORCE, 0.06), softcontact_sim::sponge()).unwrap();
    let estimator = ContactEstimatorNode::new(EstimatorConfig::default()).unwrap();
    Cell::new(config, controller, estimator).unwrap()
}

/// The arm's physical limits and the force limit, this cycle.
fn assert_within_limits(sim: &Simulator, when: &str) {
    for (i, j) in lwr4::model().joints.iter().enumerate() {
        let (q, dq) = (sim.q()[i], sim.dq()[i]);
        assert!(q >= j.limits.lower && q <= j.limits.upper, "{when}: joint {} at {q} rad", i + 1);
        assert!(dq.abs() <= j.limits.velocity, "{when}: joint {} at {dq} rad/s", i + 1);
    }
    let f = sim.contact().normal_force;
    assert!(f <= 1.2 * MAX_FORCE, "{when}: {f} N on the sponge");
}

/// What the cycles in between showed.
#[derive(Debug, Default)]
struct Seen {
    /// Cycles the KRC commanded in another strategy than joint impedance, and in those the largest
    /// torque the driver added.
    other_strategy: usize,
    added_torque: f32,
    /// Cycles the controller computed a torque.
    controller_ticks: usize,
    /// The farthest the hand went from where it started [m].
    moved: f64,
}

/// Runs `cycles` cycles checking the limits; what the KRC and the driver did.
fn run(cell: &mut Cell, cycles: usize) -> Seen {
    let start = cell.lockstep.sim.tool_pose().translation.vector;
    let mut seen = Seen::default();
    for k in 0..cycles {
        let state = cell.lockstep.sim.krc.state();
        let strategy = cell.lockstep.sim.krc.strategy();
        let tick = cell.cycle().unwrap();
        if state == InterfaceState::Command && strategy != STRATEGY_JOINT_IMPEDANCE {
            seen.other_strategy += 1;
            let added = cell.lockstep.sim.krc.last_command().unwrap().add_jnt_trq;
            seen.added_torque = added.iter().fold(seen.added_torque, |m, t| m.max(t.abs()));
        }
        seen.controller_ticks += usize::from(tick.is_some_and(|t| t.torque.is_some()));
        assert_within_limits(&cell.lockstep.sim, &format!("cycle {k}"));
        seen.moved = seen.moved.max((cell.lockstep.sim.tool_pose().translation.vector - start).norm());
    }
    seen
}

#[test]
fn a_krc_in_position_control_gets_no_torque_and_the_controller_does_not_wind_up() {
    // A KRL program that starts position control whatever it is asked: the driver asks it once to stop
    // and start joint impedance, then leaves it and says why.
    let mut cell = cell(KrlProgram::Fixed(STRATEGY_POSITION), 31);
    let seen = run(&mut cell, 10_000);
    assert_eq!(cell.lockstep.sim.krc.state(), InterfaceState::Command);
    assert!(seen.other_strategy > 9_000, "{seen:?}");
    assert_eq!(seen.added_torque, 0.0, "{seen:?}");
    assert_eq!(seen.controller_ticks, 0, "the controller integrated while its torques were not applied");
    assert!(seen.moved < 1e-4, "the hand moved {:.3} mm", seen.moved * 1e3);
    assert!(cell.lockstep.driver.krl_ignores_strategy());
    let out = cell.lockstep.driver.handle(&cell.lockstep.sim.measurement().encode()).unwrap().1;
    assert_eq!(out.waiting, Some(Waiting::StrategyKept(ControlMode::Position)));
    assert!(out.waiting.unwrap().to_string().contains("krl/softcontact.src"));
    // The controller's law has not moved on: no time, no contact, no plan.
    assert_eq!(cell.controller.law.time(), 0.0);
    assert_eq!(cell.controller.counters.ticks, 0);
}

#[test]
fn ros_control_src_starts_position_control_first_and_the_driver_takes_it_to_joint_impedance() {
    let mut cell = cell(KrlProgram::RosControl, 32);
    let seen = run(&mut cell, 3_000);
    assert!(seen.other_strategy > 0, "ros_control.src's first start is position control: {seen:?}");
    assert_eq!(seen.added_torque, 0.0);
    assert_eq!(
        (cell.lockstep.sim.krc.state(), cell.lockstep.sim.krc.strategy()),
        (InterfaceState::Command, STRATEGY_JOINT_IMPEDANCE)
    );
    assert!(seen.controller_ticks > 1_000, "{seen:?}");
    // And it presses as it should.
    let seen = run(&mut cell, 6_000);
    assert!(seen.controller_ticks == 6_000, "{seen:?}");
    assert!(cell.controller.law.contact_level().is_some(), "contact found");
}

/// The shipped program: pressing at 60 N, settled.
fn pressing(seed: u64) -> Cell {
    let mut cell = cell(KrlProgram::Softcontact, seed);
    let mut cycles = 0;
    while !cell.cycle().unwrap().is_some_and(|t| t.controller.in_contact) {
        cycles += 1;
        assert!(cycles < 10_000, "no contact");
    }
    cell.controller.law.command_force(60.0, 1.0).unwrap();
    run(&mut cell, 1500);
    cell
}

#[test]
fn a_strategy_switched_mid_press_gets_no_torque_and_the_controller_approaches_again_after() {
    for (strategy, what) in [(STRATEGY_POSITION, "position"), (20, "Cartesian impedance")] {
        let mut cell = pressing(33);
        let session = cell.lockstep.driver.session();
        let before = cell.lockstep.sim.contact().normal_force;
        cell.lockstep.sim.krc.switch_strategy(strategy);
        // The driver asks the program to stop; the shipped one starts joint impedance again.
        let seen = run(&mut cell, 4_000);
        assert!(seen.other_strategy > 0 && seen.added_torque == 0.0, "{what}: {seen:?}");
        assert!(seen.moved < 3e-3, "{what}: the hand moved {:.1} mm", seen.moved * 1e3);
        assert_eq!(cell.lockstep.sim.krc.strategy(), STRATEGY_JOINT_IMPEDANCE, "{what}");
        assert_ne!(cell.lockstep.driver.session(), session, "{what}: torque mode again is a new session");
        let after = cell.lockstep.sim.contact().normal_force;
        assert!(after > 0.5 * before && after < 1.2 * before, "{what}: {before} N before, {after} N after");
        assert!(cell.controller.law.contact_level().is_some(), "{what}: contact found again");
    }
}

#[test]
fn drives_off_or_a_drive_error_mid_press_get_no_torque_and_the_arm_stays_put() {
    for (power, error, what) in [(0x3F, 0, "drive 7 off"), (0x7F, 0x10, "a drive error")] {
        let mut cell = pressing(34);
        let before = cell.lockstep.sim.contact().normal_force;
        (cell.lockstep.sim.krc.power, cell.lockstep.sim.krc.error) = (power, error);
        let seen = run(&mut cell, 3_000);
        assert_eq!(seen.controller_ticks, 0, "{what}: {seen:?}");
        assert!(seen.moved < 1e-4, "{what}: the hand moved {:.3} mm", seen.moved * 1e3);
        let out = cell.lockstep.driver.handle(&cell.lockstep.sim.measurement().encode()).unwrap().1;
        assert!(matches!(out.waiting, Some(Waiting::DrivesOff(_) | Waiting::DriveError(_))), "{what}: {out:?}");
        (cell.lockstep.sim.krc.power, cell.lockstep.sim.krc.error) = (0x7F, 0);
        let seen = run(&mut cell, 3_000);
        assert!(seen.controller_ticks > 2_000, "{what}: torque mode again: {seen:?}");
        let after = cell.lockstep.sim.contact().normal_force;
        assert!(after > 0.5 * before && after < 1.2 * before, "{what}: {before} N before, {after} N after");
    }
}

#[test]
fn a_latched_fault_fails_force_commands_with_its_reason_until_the_operator_restarts_the_krl_program() {
    use softcontact_nodes::deformation_controller::ControlError;
    let mut cell = pressing(35);
    // A forged measurement from the KRC: joint 2 jumped 0.15 rad in a cycle. Latched as it is read.
    let mut forged = cell.lockstep.sim.measurement();
    forged.data.msr_jnt_pos[1] += 0.15;
    let measured = cell.lockstep.driver.measure(&forged.encode()).unwrap();
    assert!(!measured.output.torque_mode(), "the controller is never given it in torque mode");
    cell.lockstep.driver.answer(measured);
    // Held where the arm was before the jump, with no torque of the command: the sponge pushes the hand
    // back against the hold's spring, never the other way.
    let before = cell.lockstep.sim.contact().normal_force;
    let seen = run(&mut cell, 1_000);
    let after = cell.lockstep.sim.contact().normal_force;
    assert_eq!(seen.controller_ticks, 0, "{seen:?}");
    assert!(seen.moved < 10e-3 && after <= before + 0.5, "{:.2} mm, {before:.1} → {after:.1} N", seen.moved * 1e3);
    // Silence, new sessions and the KRC's own fallback do not clear it.
    cell.lockstep.driver.resumed_after(1.36);
    cell.lockstep.driver.begin_session();
    let seen = run(&mut cell, 2_000);
    assert_eq!(seen.controller_ticks, 0, "{seen:?}");
    assert!(
        seen.moved < 10e-3 && cell.lockstep.sim.contact().normal_force <= before + 0.5,
        "{:.2} mm",
        seen.moved * 1e3
    );
    assert!(cell.lockstep.driver.fault().is_some());
    match cell.controller.on_force_command(60.0, 1.0) {
        (_, Err(ControlError::DriverFault(why))) => assert!(why.contains("joint 2 overspeed"), "{why}"),
        other => panic!("a force command while the fault stands: {other:?}"),
    }
    // The operator restarts the KRL program: the fault clears, the controller approaches again.
    let q = *cell.lockstep.sim.q();
    cell.lockstep.sim.krc.restart_program(q);
    let seen = run(&mut cell, 8_000);
    assert!(cell.lockstep.driver.fault().is_none() && cell.lockstep.driver.counters.faults_cleared == 1);
    assert!(seen.controller_ticks > 1_000, "{seen:?}");
    assert!(cell.controller.law.contact_level().is_some(), "contact found again");
    let (_, taken) = cell.controller.on_force_command(60.0, 1.0);
    assert!(taken.is_ok(), "{taken:?}");
}
