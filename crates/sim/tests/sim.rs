//! The simulator against the dynamics it integrates, the FRI rules the KRC enforces, and the physics of
//! the surface and the sensor.

use nalgebra::Vector3;
use softcontact_contact::{ContactModel, Kind};
use softcontact_dynamics::lwr4;
use softcontact_sim::{FtSensorConfig, KrcEvent, SimConfig, Simulator};
use softcontact_wire::fri::{self, InterfaceState, Quality, flags};
use softcontact_wire::rdt::Calibration;

/// The remote's answer to a measurement: joint impedance with zero stiffness, mirroring the measured
/// position, with an additional torque.
fn answer(m: &fri::Measurement, seq: u16, start: bool, torque: [f64; 7]) -> fri::Command {
    let mut c = fri::Command::default();
    c.header.send_seq = seq;
    c.header.refl_seq = m.header.send_seq;
    c.krl.int[0] = 30;
    c.krl.int[1] = i32::from(start);
    c.flags = flags::JOINT_IMPEDANCE;
    c.jnt_pos = m.data.msr_jnt_pos;
    c.jnt_damping = [0.7; 7];
    c.add_jnt_trq = torque.map(|t| t as f32);
    c
}

/// Answers every cycle in monitor mode until quality is perfect, then asks to start.
fn enter_command(sim: &mut Simulator) -> u16 {
    let mut seq = 0u16;
    for _ in 0..200 {
        let m = sim.measurement();
        seq = seq.wrapping_add(1);
        let start = m.intf.quality == Quality::Perfect;
        if let Some(KrcEvent::EnteredCommand) = sim.command(&answer(&m, seq, start, [0.0; 7])) {
            sim.step_cycle().unwrap();
            return seq;
        }
        sim.step_cycle().unwrap();
    }
    panic!("the KRC never entered command mode");
}

fn free_config() -> SimConfig {
    SimConfig {
        surface: None,
        sensor: FtSensorConfig::ideal(),
        ..SimConfig::above_surface(ContactModel::new(Kind::KelvinVoigt, 1.0, 0.0).unwrap(), 1)
    }
}

#[test]
fn command_mode_needs_perfect_quality_and_a_mirrored_position() {
    let mut sim = Simulator::new(free_config()).unwrap();
    let m = sim.measurement();
    assert_eq!(m.intf.state, InterfaceState::Monitor);
    assert_eq!(m.intf.quality, Quality::Unacceptable, "no history yet");
    assert_eq!(sim.command(&answer(&m, 1, true, [0.0; 7])), None, "start refused before the timing is proven");
    sim.step_cycle().unwrap();
    // Perfect timing, but a command that does not mirror the current position.
    let mut seq = 1;
    for _ in 0..100 {
        let m = sim.measurement();
        seq += 1;
        sim.command(&answer(&m, seq, false, [0.0; 7]));
        sim.step_cycle().unwrap();
    }
    let m = sim.measurement();
    let mut off = answer(&m, seq + 1, true, [0.0; 7]);
    off.jnt_pos[3] += 0.01;
    assert_eq!(sim.command(&off), Some(KrcEvent::InterpolationError));
    sim.step_cycle().unwrap();
    let seq = enter_command(&mut sim);
    assert_eq!(sim.krc.state(), InterfaceState::Command);
    // Changing the flags in command mode is fatal.
    let m = sim.measurement();
    let mut changed = answer(&m, seq + 1, true, [0.0; 7]);
    changed.flags = flags::JNT_POS;
    assert!(matches!(sim.command(&changed), Some(KrcEvent::FellBack(r)) if r.contains("cmdFlags")));
}

#[test]
fn missing_answers_bring_the_krc_back_to_monitor() {
    let mut sim = Simulator::new(free_config()).unwrap();
    enter_command(&mut sim);
    let mut event = None;
    for _ in 0..6 {
        sim.measurement();
        event = sim.step_cycle().unwrap().or(event);
    }
    assert!(matches!(&event, Some(KrcEvent::FellBack(r)) if r.contains("consecutive")), "{event:?}");
    assert_eq!(sim.krc.state(), InterfaceState::Monitor);
    let q = *sim.q();
    for _ in 0..100 {
        sim.measurement();
        sim.step_cycle().unwrap();
    }
    assert_eq!(*sim.q(), q, "the brakes hold the arm");
}

#[test]
fn zero_additional_torque_holds_the_arm_still() {
    let mut sim = Simulator::new(free_config()).unwrap();
    let mut seq = enter_command(&mut sim);
    let q0 = *sim.q();
    for _ in 0..2000 {
        let m = sim.measurement();
        seq = seq.wrapping_add(1);
        sim.command(&answer(&m, seq, true, [0.0; 7]));
        sim.step_cycle().unwrap();
    }
    let drift = sim.q().iter().zip(&q0).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(drift < 1e-9, "the KRC's gravity compensation holds the arm: drift {drift} rad after 2 s");
    assert_eq!(sim.krc.state(), InterfaceState::Command);
}

/// A constant additional torque moves the arm as forward dynamics says (independent RK4 reference).
#[test]
fn constant_torque_produces_the_predicted_motion() {
    let mut sim = Simulator::new(free_config()).unwrap();
    let mut seq = enter_command(&mut sim);
    // Small enough that no joint reaches its velocity limit (the KRC would brake).
    let torque = [0.0, 0.0, 0.0, 0.0, 0.02, 0.03, 0.005];
    let (q0, dq0) = (*sim.q(), *sim.dq());
    for _ in 0..200 {
        let m = sim.measurement();
        seq = seq.wrapping_add(1);
        sim.command(&answer(&m, seq, true, torque));
        sim.step_cycle().unwrap();
    }
    // Reference: τ_motor = g(q) + τ, so q̈ = M⁻¹ τ exactly (h − g = C q̇ remains); RK4 at 0.1 ms.
    let model = lwr4::model();
    let mut data = model.data();
    let accel = |q: &[f64; 7], dq: &[f64; 7], data: &mut softcontact_dynamics::Data| -> [f64; 7] {
        let g = model.gravity_torques(data, q).clone();
        let tau: Vec<f64> = (0..7).map(|i| g[i] + torque[i]).collect();
        model.forward_dynamics(data, q, dq, &tau, None).unwrap().as_slice().try_into().unwrap()
    };
    let (mut q, mut dq) = (q0, dq0);
    let h = 1e-4;
    for _ in 0..2000 {
        let add = |a: &[f64; 7], b: &[f64; 7], s: f64| -> [f64; 7] { std::array::from_fn(|i| a[i] + s * b[i]) };
        let k1v = accel(&q, &dq, &mut data);
        let k1q = dq;
        let k2v = accel(&add(&q, &k1q, h / 2.0), &add(&dq, &k1v, h / 2.0), &mut data);
        let k2q = add(&dq, &k1v, h / 2.0);
        let k3v = accel(&add(&q, &k2q, h / 2.0), &add(&dq, &k2v, h / 2.0), &mut data);
        let k3q = add(&dq, &k2v, h / 2.0);
        let k4v = accel(&add(&q, &k3q, h), &add(&dq, &k3v, h), &mut data);
        let k4q = add(&dq, &k3v, h);
        for i in 0..7 {
            q[i] += h / 6.0 * (k1q[i] + 2.0 * k2q[i] + 2.0 * k3q[i] + k4q[i]);
            dq[i] += h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
        }
    }
    assert_eq!(sim.krc.state(), InterfaceState::Command, "{:?}", sim.krc.last_fault());
    let moved = q.iter().zip(&q0).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    let err = sim.q().iter().zip(&q).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(moved > 0.05, "the wrist should move noticeably: {moved} rad");
    assert!(err < 0.01 * moved, "simulated {:?} vs predicted {q:?}: error {err} of {moved}", sim.q());
}

#[test]
fn pressing_a_surface_gives_the_model_force_and_the_sensor_reads_it() {
    let model = ContactModel::new(Kind::KelvinVoigt, 1857.0, 60.0).unwrap();
    let mut config = SimConfig::above_surface(model, 2);
    config.sensor = FtSensorConfig::ideal();
    let mut sim = Simulator::new(config).unwrap();
    let mut seq = enter_command(&mut sim);
    // Push down with 30 N at the hand through Jᵀ and let it settle on the dice (k = 1857 N/m).
    let arm = lwr4::model();
    let mut data = arm.data();
    let tool = arm.frame_id(lwr4::TOOL_FRAME).unwrap();
    let mut jac = nalgebra::Matrix6xX::zeros(7);
    for i in 0..6000 {
        let m = sim.measurement();
        let q: [f64; 7] = std::array::from_fn(|k| m.data.msr_jnt_pos[k] as f64);
        arm.forward_kinematics(&mut data, &q);
        arm.frame_jacobian(&data, tool, softcontact_dynamics::Axes::World, &mut jac);
        // Joint damping keeps the push quasi-static: τ = Jᵀ(0, 0, −30, 0, 0, 0) − 2 q̇.
        let push = jac.transpose() * nalgebra::Vector6::new(0.0, 0.0, -30.0, 0.0, 0.0, 0.0);
        let torque: [f64; 7] = std::array::from_fn(|k| push[k] - 2.0 * sim.dq()[k]);
        seq = seq.wrapping_add(1);
        sim.command(&answer(&m, seq, true, torque));
        sim.step_cycle().unwrap();
        if i == 5999 {
            let c = *sim.contact();
            assert!((c.normal_force - 30.0).abs() < 0.3, "settled normal force {} N", c.normal_force);
            assert!((c.normal_force - (1857.0 * c.deformation + 60.0 * c.rate)).abs() < 1e-9);
            assert!((c.force - Vector3::new(0.0, 0.0, c.normal_force)).norm() < 1e-9, "the surface pushes up");
        }
    }
    // Ideal sensor: reads the contact force and the hand's weight in its own frame (z down: Fz < 0).
    let record = sim.ft_record();
    let si = Calibration::gamma_si_130_10().to_si(&record.counts);
    let f = sim.contact().normal_force;
    let weight = 0.20 * 9.81;
    let sensor_z_down = -1.0;
    assert!((si[2] - sensor_z_down * f - weight).abs() < 0.05, "Fz {} vs −{f} + {weight}", si[2]);
    assert!(si[0].abs() < 0.6 && si[1].abs() < 0.6, "little lateral force: {si:?}");
}

#[test]
fn runs_are_deterministic_for_a_seed() {
    let run = |seed| {
        let mut sim =
            Simulator::new(SimConfig::above_surface(ContactModel::new(Kind::HuntCrossley, 2e4, 500.0).unwrap(), seed))
                .unwrap();
        enter_command(&mut sim);
        (sim.measurement().encode().to_vec(), sim.ft_record())
    };
    assert_eq!(run(5), run(5));
    assert_ne!(run(5).1, run(6).1, "the noise depends on the seed");
}

#[test]
fn bad_configurations_are_refused() {
    let mut c = free_config();
    c.step = 3e-4; // 1 ms is not a whole number of 0.3 ms steps
    assert!(Simulator::new(c).is_err());
    let mut c = free_config();
    c.initial_q[1] = 3.0;
    assert!(Simulator::new(c).is_err());
}

#[test]
fn exceeding_a_joint_velocity_limit_trips_the_krc() {
    let mut sim = Simulator::new(free_config()).unwrap();
    let mut seq = enter_command(&mut sim);
    for _ in 0..300 {
        let m = sim.measurement();
        seq = seq.wrapping_add(1);
        sim.command(&answer(&m, seq, true, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5]));
        sim.step_cycle().unwrap();
    }
    assert_eq!(sim.krc.state(), InterfaceState::Monitor);
    assert!(sim.krc.last_fault().unwrap().contains("lwr_a6_joint exceeded its velocity limit"));
    assert!(sim.dq().iter().all(|v| *v == 0.0), "braked");
}

#[test]
fn the_walton_tangential_law_sticks_then_slides_at_the_friction_cone() {
    use softcontact_contact::Tangential;
    use softcontact_sim::{Surface, SurfaceConfig};
    let model = ContactModel {
        tangential: Some(Tangential::walton(4.0e4, 0.5)),
        ..ContactModel::new(Kind::HertzWalton, 2.0e4, 0.0).unwrap()
    };
    let mut surface = Surface::new(SurfaceConfig::new(Vector3::zeros(), Vector3::new(0.0, 0.0, -1.0), model)).unwrap();
    // Press 1 cm in, then drag along x.
    let v = Vector3::zeros();
    let c = surface.contact(&Vector3::new(0.0, 0.0, -0.01), &v, 1e-3).unwrap();
    let fn_ = 2.0e4 * 0.01f64.powf(1.5);
    assert!((c.force - Vector3::new(0.0, 0.0, fn_)).norm() < 1e-9, "pure normal force at first touch");
    // A small drag sticks: f_t = k_t √z δ, opposing the motion.
    let c = surface.contact(&Vector3::new(0.0005, 0.0, -0.01), &v, 1e-3).unwrap();
    assert!(!c.sliding && (c.force.x + 4.0e4 * 0.1 * 0.0005).abs() < 1e-9, "{:?}", c.force);
    // A long drag slides: |f_t| = μ f_n, and stays there as the drag goes on.
    for x in [0.01, 0.02, 0.03] {
        let c = surface.contact(&Vector3::new(x, 0.0, -0.01), &v, 1e-3).unwrap();
        assert!(c.sliding && (c.force.x + 0.5 * fn_).abs() < 1e-9, "at {x}: {:?}", c.force);
    }
    // Coming back a little: the anchor moved with the slip, so the contact sticks again.
    let c = surface.contact(&Vector3::new(0.0299, 0.0, -0.01), &v, 1e-3).unwrap();
    assert!(!c.sliding && c.force.x < 0.0 && c.force.x.abs() < 0.5 * fn_);
    // Leaving the surface releases everything.
    assert_eq!(surface.contact(&Vector3::new(0.03, 0.0, 0.001), &v, 1e-3).unwrap().force, Vector3::zeros());
}

#[test]
fn joint_friction_dissipates_energy() {
    use softcontact_sim::JointFriction;
    let swing = |friction: Option<JointFriction>| {
        let mut config = free_config();
        config.friction = friction;
        let mut sim = Simulator::new(config).unwrap();
        let mut seq = enter_command(&mut sim);
        // Spin the wrist up with a torque pulse, then let it coast.
        for i in 0..600 {
            let m = sim.measurement();
            seq = seq.wrapping_add(1);
            let t = if i < 100 { 0.004 } else { 0.0 };
            sim.command(&answer(&m, seq, true, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, t]));
            sim.step_cycle().unwrap();
        }
        sim.dq()[6]
    };
    let free = swing(None);
    let damped = swing(Some(JointFriction { viscous: [0.002; 7], coulomb: [0.0005; 7] }));
    assert!(free > 0.1, "the wrist coasts without friction: {free} rad/s");
    assert!(damped >= 0.0 && damped < 0.5 * free, "friction slows it: {damped} vs {free} rad/s");
}

#[test]
fn a_surface_models_crosstalk_reads_tangential_load_as_normal_force() {
    use softcontact_contact::{Effect, Tangential};
    use softcontact_sim::{Surface, SurfaceConfig};
    let model = ContactModel {
        tangential: Some(Tangential::walton(4.0e4, 0.5)),
        effects: vec![Effect::SensorCrosstalk { coupling: [0.02, 0.0, 0.0] }],
        ..ContactModel::new(Kind::HertzWalton, 2.0e4, 0.0).unwrap()
    };
    let mut surface = Surface::new(SurfaceConfig::new(Vector3::zeros(), Vector3::new(0.0, 0.0, -1.0), model)).unwrap();
    let v = Vector3::zeros();
    surface.contact(&Vector3::new(0.0, 0.0, -0.01), &v, 1e-3).unwrap();
    let c = surface.contact(&Vector3::new(0.0005, 0.0, -0.01), &v, 1e-3).unwrap();
    // F_t = (−2, 0, 0) N on the hand: the normal reading is 0.02 × (−2) N off, the true force is not.
    assert!((c.force.x + 2.0).abs() < 1e-9);
    assert!((c.measured_normal_force - (c.normal_force - 0.04)).abs() < 1e-12, "{c:?}");
    assert!((c.sensed_force.z - (c.force.z - 0.04)).abs() < 1e-12 && c.sensed_force.x == c.force.x);
}

/// A hidden payload on the flange: the KRC compensates the URDF's gravity only, so with no torque
/// commanded the arm sags under the payload's weight; without one the arm holds.
#[test]
fn a_hidden_payload_weighs_on_the_arm_and_only_there() {
    use softcontact_sim::Payload;
    let hold = |payload: Option<Payload>| {
        let mut config = free_config();
        config.payload = payload;
        let mut sim = Simulator::new(config).unwrap();
        let mut seq = enter_command(&mut sim);
        let q0 = *sim.q();
        for _ in 0..300 {
            let m = sim.measurement();
            seq = seq.wrapping_add(1);
            sim.command(&answer(&m, seq, true, [0.0; 7]));
            sim.step_cycle().unwrap();
        }
        // How far any joint moved.
        sim.q().iter().zip(&q0).fold(0.0f64, |d, (a, b)| d.max((a - b).abs()))
    };
    let still = hold(None);
    let sagged = hold(Some(Payload { mass: 1.0, com: [0.0, 0.0, 0.02] }));
    assert!(still < 1e-6, "without a payload the arm holds: {still} rad");
    assert!(sagged > 1e-3, "a kilogram the KRC does not know pulls the arm down: {sagged} rad");
    let bad = SimConfig { payload: Some(Payload { mass: f64::NAN, com: [0.0; 3] }), ..free_config() };
    assert!(Simulator::new(bad).is_err());
}

/// Answers in monitor mode with `strategy` asked and `flags`, until the KRC enters command mode or
/// refuses; the event.
fn ask_start(sim: &mut Simulator, strategy: i32, flags: u32) -> Option<KrcEvent> {
    for seq in 1..300u16 {
        let m = sim.measurement();
        let mut c = answer(&m, seq, m.intf.quality == Quality::Perfect, [0.0; 7]);
        (c.krl.int[0], c.flags) = (strategy, flags);
        c.cart_pos = m.data.msr_cart_pos;
        let event = sim.command(&c);
        sim.step_cycle().unwrap();
        if event.is_some() {
            return event;
        }
    }
    None
}

#[test]
fn the_krc_reports_the_strategy_the_krl_program_selected_in_every_state() {
    use softcontact_sim::{KrlProgram, STRATEGY_JOINT_IMPEDANCE, STRATEGY_POSITION};
    // Both programs begin in position control, reported in monitor mode too.
    let mut sim = Simulator::new(free_config()).unwrap();
    let m = sim.measurement();
    assert_eq!((m.intf.state, m.robot.control), (InterfaceState::Monitor, fri::ControlMode::Position));
    assert_eq!(m.krl.int[1], 10, "$FRI_TO_INT[2]: the program just began");
    // The SDK's doPositionControl: strategy 10 with jntPos alone enters command mode in position control.
    assert_eq!(ask_start(&mut sim, STRATEGY_POSITION, flags::JNT_POS), Some(KrcEvent::EnteredCommand));
    let m = sim.measurement();
    assert_eq!((m.intf.state, m.robot.control), (InterfaceState::Command, fri::ControlMode::Position));
    assert_eq!((m.krl.int[0], m.krl.int[1]), (STRATEGY_POSITION, 1), "softcontact.src reports the strategy");
    // Position control follows jntPos, whatever torque is added.
    let q0 = *sim.q();
    for seq in 1000..1500u16 {
        let m = sim.measurement();
        let mut c = answer(&m, seq, true, [0.0, 50.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        c.flags = flags::JNT_POS;
        c.jnt_pos = q0.map(|v| v as f32);
        c.jnt_pos[0] += 0.01;
        sim.command(&c);
        sim.step_cycle().unwrap();
    }
    assert!((sim.q()[0] - (q0[0] + 0.01)).abs() < 1e-6 && (sim.q()[1] - q0[1]).abs() < 1e-6, "{:?}", sim.q());

    // ros_control.src keeps position control on its first start, joint impedance asked or not.
    let mut config = free_config();
    config.krc.program = KrlProgram::RosControl;
    let mut sim = Simulator::new(config).unwrap();
    assert_eq!(ask_start(&mut sim, STRATEGY_JOINT_IMPEDANCE, flags::JOINT_IMPEDANCE), Some(KrcEvent::EnteredCommand));
    let m = sim.measurement();
    assert_eq!((m.robot.control, m.krl.int[0]), (fri::ControlMode::Position, 0), "no strategy reported");
}

#[test]
fn the_krc_says_why_it_refuses_a_start() {
    let mut sim = Simulator::new(free_config()).unwrap();
    let refused = ask_start(&mut sim, 40, flags::JOINT_IMPEDANCE);
    assert!(matches!(&refused, Some(KrcEvent::Refused(r)) if r.contains("unknown strategy 40")), "{refused:?}");
    let refused = ask_start(&mut sim, 20, flags::JOINT_IMPEDANCE);
    assert!(matches!(&refused, Some(KrcEvent::Refused(r)) if r.contains("cmdFlags")), "{refused:?}");
    assert_eq!(ask_start(&mut sim, 20, flags::CART_POS), Some(KrcEvent::EnteredCommand));
    assert_eq!(sim.measurement().robot.control, fri::ControlMode::CartesianImpedance);
}

#[test]
fn a_restarted_krl_program_is_in_monitor_mode_with_its_init_flag() {
    let mut sim = Simulator::new(free_config()).unwrap();
    enter_command(&mut sim);
    sim.krc.restart_program(*sim.q());
    let m = sim.measurement();
    assert_eq!(
        (m.intf.state, m.robot.control, m.krl.int[1]),
        (InterfaceState::Monitor, fri::ControlMode::Position, 10)
    );
}
