//! The nodes' logic without sockets: driver replies and the F/T node's arithmetic.

use nalgebra::{UnitQuaternion, Vector3};
use softcontact_dynamics::lwr4;
use softcontact_nodes::ft_sensor::{Biquad, FtConfig, FtSensorNode};
use softcontact_nodes::lwr_driver::{DriverError, Fault, LwrDriver, Params as DriverParams, Waiting};
use softcontact_nodes::runtime::writer_pin::WriterRefused;
use softcontact_wire::fri::{self, InterfaceState, Quality, flags};
use softcontact_wire::rdt::{Calibration, Record, Status};

fn measurement(seq: u16, state: InterfaceState, q: [f32; 7], gravity: [f32; 7]) -> Vec<u8> {
    let mut m = fri::Measurement::decode(&{
        let mut b = vec![0u8; fri::MEASUREMENT_SIZE];
        b[4..6].copy_from_slice(&(fri::MEASUREMENT_SIZE as u16).to_le_bytes());
        b[6..8].copy_from_slice(&fri::MEASUREMENT_ID.to_le_bytes());
        b
    })
    .unwrap();
    m.header.send_seq = seq;
    m.intf.state = state;
    m.intf.quality = Quality::Perfect;
    m.intf.desired_msr_sample_time = 0.001;
    m.robot.power = 0x7F;
    // In command state: the shipped KRL program started joint impedance.
    if state == InterfaceState::Command {
        m.robot.control = fri::ControlMode::JointImpedance;
        (m.krl.int[0], m.krl.int[1]) = (30, 1);
    }
    m.data.msr_jnt_pos = q;
    m.data.cmd_jnt_pos = q;
    m.data.cmd_jnt_pos_fri_offset[0] = 0.001;
    m.data.gravity = gravity;
    m.encode().to_vec()
}

const Q: [f32; 7] = [0.0, 0.5, 0.0, -1.4, 0.0, 1.2, 0.0];
/// The DDS writer of the controller's commands, and of someone else's.
const CONTROLLER: [u8; 16] = [1; 16];
const STRANGER: [u8; 16] = [2; 16];
/// The driver's clock at the measurement a command in these tests answers \[s\].
const NOW: f64 = 10.0;
const G: [f32; 7] = [0.0, -30.0, 0.5, 10.0, -0.2, 0.9, 0.0];

#[test]
fn in_command_mode_the_krc_gravity_is_removed_from_the_total_torque() {
    let mut d = LwrDriver::new(DriverParams::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&[1.0, -28.0, 0.5, 12.0, -0.2, 1.0, 0.3]).unwrap();
    let (reply, out) = d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap();
    assert_eq!(reply.flags, flags::JOINT_IMPEDANCE);
    assert_eq!(reply.header.refl_seq, 2);
    assert_eq!(reply.jnt_stiffness, [0.0; 7], "torque control is joint impedance with zero stiffness");
    assert_eq!(reply.jnt_pos, Q, "mirrors the measured position");
    let expected = [1.0, 2.0, 0.0, 2.0, 0.0, 0.1, 0.3];
    for (i, (sent, want)) in reply.add_jnt_trq.iter().zip(expected).enumerate() {
        assert!((*sent as f64 - want).abs() < 1e-5, "joint {i}: {sent}");
    }
    assert!(!out.holding);
}

#[test]
fn out_of_command_mode_the_driver_mirrors_the_krc_and_asks_to_start() {
    let mut d = LwrDriver::new(DriverParams::default());
    let (reply, _) = d.handle(&measurement(1, InterfaceState::Monitor, Q, G)).unwrap();
    assert!((reply.jnt_pos[0] - 0.001).abs() < 1e-7, "cmdJntPos + cmdJntPosFriOffset");
    assert_eq!(reply.add_jnt_trq, [0.0; 7]);
    assert_eq!((reply.krl.int[0], reply.krl.int[1]), (30, 1));
}

/// A KRC that applies a monitor-mode answer (a forged "monitor" while it commands, or the answer it
/// takes into command mode) gets a stiff spring at its own commanded position, never a floating arm.
#[test]
fn a_monitor_answer_applied_by_a_commanding_krc_holds_the_arm_instead_of_floating_it() {
    let mut d = LwrDriver::new(DriverParams::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&[1.0, -28.0, 0.5, 12.0, -0.2, 1.0, 0.3]).unwrap();
    let (reply, _) = d.handle(&measurement(2, InterfaceState::Monitor, Q, G)).unwrap();
    let stiff = DriverParams::default().hold_stiffness.map(|k| k as f32);
    assert_eq!(reply.jnt_stiffness, stiff, "the hold's stiffness");
    assert_eq!(reply.add_jnt_trq, [0.0; 7], "no torque of the command");
}

/// In position control (or any strategy but joint impedance) the set point is where the arm was when
/// the driver began to hold (here the first measurement, without a command): measured positions that drift — a KRC applying it in joint impedance after all, a
/// forged measurement — never drag it along.
#[test]
fn outside_joint_impedance_the_set_point_stays_where_the_arm_was_however_the_measurement_drifts() {
    let mut d = LwrDriver::new(DriverParams::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    for seq in 2..300u16 {
        let drift = 1e-4 * seq as f32;
        let datagram = commanding_with(seq, |m| {
            m.robot.control = fri::ControlMode::Position;
            m.data.msr_jnt_pos = Q.map(|q| q + drift);
        });
        let (reply, out) = d.handle(&datagram).unwrap();
        assert!(out.holding);
        for (i, (sent, first)) in reply.jnt_pos.iter().zip(Q).enumerate() {
            assert!((sent - first).abs() < 1e-6, "joint {i}: set point {sent} followed the drift");
        }
    }
}

/// The driver sends the total torque less the KRC's gravity: a gravity that jumps between two
/// measurements (+60 N·m on A2 in one cycle) would step the torque at the arm past any rate limit. In
/// command mode it is refused unanswered; a gravity that changes as fast as the arm can move it is
/// taken, and outside command mode (no torque applied) the reference follows the KRC.
#[test]
fn a_krc_gravity_that_jumps_in_command_mode_is_refused_and_one_that_follows_the_arm_is_taken() {
    let mut d = LwrDriver::new(DriverParams::default());
    let with_gravity = |seq: u16, state, offset: f32| {
        let mut g = G;
        g[1] += offset;
        measurement(seq, state, Q, g)
    };
    d.handle(&with_gravity(1, InterfaceState::Command, 0.0)).unwrap();
    // 0.4 N·m a millisecond: faster than the LWR's gravity changes at its velocity limits.
    for seq in 2..50u16 {
        d.handle(&with_gravity(seq, InterfaceState::Command, 0.4 * seq as f32)).unwrap();
    }
    for (seq, jump) in [(50u16, 60.0), (51, -100.0), (52, 150.0), (53, 3.0)] {
        let err = d.handle(&with_gravity(seq, InterfaceState::Command, 0.4 * 49.0 + jump)).unwrap_err();
        assert!(matches!(err, DriverError::Implausible(_)) && err.to_string().contains("gravity"), "{jump}: {err}");
    }
    assert_eq!(d.counters.implausible, 4);
    // The next measurement like the last one taken is answered; a lost measurement widens the step.
    d.handle(&with_gravity(54, InterfaceState::Command, 0.4 * 49.0)).unwrap();
    d.handle(&with_gravity(57, InterfaceState::Command, 0.4 * 49.0 + 1.4)).unwrap();
    // Out of command mode the KRC's gravity is taken whatever it did (a new load, set in KRL).
    d.handle(&with_gravity(58, InterfaceState::Monitor, 40.0)).unwrap();
    d.handle(&with_gravity(59, InterfaceState::Command, 40.0)).unwrap();
}

#[test]
fn a_bad_command_is_refused_and_the_driver_holds_at_once() {
    // Safety class 1: a non-finite value anywhere means hold, never "repeat the last torque".
    for bad in [&[0.0; 6][..], &[0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0], &[f64::INFINITY; 7], &[]] {
        let mut d = LwrDriver::new(DriverParams::default());
        d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
        d.set_command(&[5.0; 7]).unwrap();
        assert!(d.set_command(bad).is_err());
        let (reply, out) = d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap();
        assert!(out.holding, "{bad:?}");
        assert_eq!(reply.add_jnt_trq, [0.0; 7], "no torque of the earlier command survives {bad:?}");
        assert_eq!(reply.jnt_pos, Q);
        assert_eq!(d.counters.commands_refused, 1);
    }
    assert_eq!(
        LwrDriver::new(DriverParams::default()).set_command(&[0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]),
        Err(DriverError::NonFiniteCommand(2))
    );
}

#[test]
fn the_watchdog_counts_answers_not_sequence_numbers() {
    // Safety class 2: a counter that goes back (a spoofed datagram, or a KRC whose counter restarted)
    // used to freeze the watchdog, so that a 9 s old torque was applied after the controller died.
    let mut d = LwrDriver::new(DriverParams::default());
    d.handle(&measurement(1000, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&[1.0, 50.0, 0.5, -40.0, -0.2, 1.0, 0.3]).unwrap();
    let mut holding_from = None;
    for (i, seq) in [1001u16, 3, 4, 5, 6, 7, 8, 9, 10].into_iter().enumerate() {
        let (_, out) = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap();
        if out.holding && holding_from.is_none() {
            holding_from = Some(i + 1);
        }
    }
    assert_eq!(holding_from, Some(6), "stale after the watchdog's 5 answered cycles");
    assert!(d.counters.out_of_order >= 1);
}

#[test]
fn strangers_are_refused_and_a_new_port_of_the_krc_is_a_new_session() {
    // Safety class 3: only the pinned KRC is answered; class 4: port 0 is no sender.
    let krc: std::net::SocketAddr = "192.168.0.1:49938".parse().unwrap();
    let mut d = LwrDriver::new(DriverParams::default());
    assert_eq!(d.accept_sender(krc, f64::INFINITY), Some(true), "the first sender is pinned");
    assert_eq!(d.accept_sender(krc, 0.001), Some(false));
    for stranger in ["192.168.0.7:49938", "10.0.0.1:5000", "192.168.0.1:0", "[::1]:49938"] {
        assert_eq!(d.accept_sender(stranger.parse().unwrap(), 1.0), None, "{stranger}");
    }
    assert_eq!(d.counters.strangers, 4);
    // The configured KRC address refuses even the first sender if it is someone else.
    let config = DriverParams { krc_address: Some("192.168.0.1".parse().unwrap()), ..DriverParams::default() };
    let mut pinned = LwrDriver::new(config);
    assert_eq!(pinned.accept_sender("192.168.0.9:49938".parse().unwrap(), f64::INFINITY), None);
    assert_eq!(pinned.accept_sender(krc, f64::INFINITY), Some(true));

    // A restarted KRC (new port): the old command is gone, the driver holds until a command answers
    // the new session.
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    let first = d.session();
    d.set_command(&[5.0; 7]).unwrap();
    assert!(!d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap().1.holding);
    // While the KRC talks, another port of its address is a stranger (any local process could open
    // one); once it has been silent, the new port is the restarted KRC.
    assert_eq!(d.accept_sender("192.168.0.1:50001".parse().unwrap(), 0.001), None);
    assert_eq!(d.accept_sender("192.168.0.1:50001".parse().unwrap(), 0.5), Some(true));
    let (reply, out) = d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    assert!(out.holding && reply.add_jnt_trq == [0.0; 7]);
    assert_eq!(out.session, first + 1);
    assert_eq!(
        d.set_remote_command(&[5.0; 7], Some(first), NOW, NOW, CONTROLLER, || 1),
        Err(DriverError::OtherSession(Some(first), first + 1))
    );
    assert!(d.set_remote_command(&[5.0; 7], None, NOW, NOW, CONTROLLER, || 1).is_err());
    assert!(d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap().1.holding);
    // Silence longer than new_session_after is a new session too.
    d.set_remote_command(&[5.0; 7], Some(first + 1), NOW - 0.001, NOW, CONTROLLER, || 1).unwrap();
    assert!(!d.handle(&measurement(3, InterfaceState::Command, Q, G)).unwrap().1.holding);
    d.resumed_after(0.5);
    assert!(d.handle(&measurement(4, InterfaceState::Command, Q, G)).unwrap().1.holding);
    assert_eq!(d.counters.sessions, 3);
}

#[test]
fn commands_older_than_the_watchdog_by_their_stamp_are_refused() {
    // Safety class 7: a replayed command 20 min old was applied.
    let mut d = LwrDriver::new(DriverParams::default());
    d.accept_sender("127.0.0.1:40000".parse().unwrap(), f64::INFINITY);
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    let s = Some(d.session());
    for age in [1200.0, 0.021, -0.021, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(
                d.set_remote_command(&[5.0; 7], s, NOW - age, NOW, CONTROLLER, || 1),
                Err(DriverError::TooOld(..))
            ),
            "{age}"
        );
    }
    assert!(d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap().1.holding);
    d.set_remote_command(&[5.0; 7], s, NOW - 0.004, NOW, CONTROLLER, || 1).unwrap();
    assert!(!d.handle(&measurement(3, InterfaceState::Command, Q, G)).unwrap().1.holding);
    assert_eq!(d.counters.commands_too_old, 5);
}

#[test]
fn a_held_command_answers_no_measurement_once_its_stamp_is_older_than_max_command_age() {
    // Commands arriving 15–19 ms old were reused for the watchdog's 5 cycles: applied at 24 ms old; one
    // taken before a 30 ms stall of the measurements was applied after it at 37 ms.
    let mut d = LwrDriver::new(DriverParams::default());
    d.accept_sender("127.0.0.1:40000".parse().unwrap(), f64::INFINITY);
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    let s = Some(d.session());
    for arrival_age in [0.0155, 0.0175, 0.0195] {
        d.set_remote_command(&[5.0; 7], s, NOW - arrival_age, NOW, CONTROLLER, || 1).unwrap();
        let mut applied = 0;
        for _ in 0..5 {
            let seq = 2 + d.counters.measurements as u16;
            let (reply, out) = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap();
            if !out.holding {
                applied += 1;
                assert!(reply.add_jnt_trq.iter().any(|t| *t != 0.0));
            }
        }
        // Answered 1 ms apart from the cycle after its arrival on: applied while 20 ms old at most.
        let expected = ((0.020 - arrival_age) / 0.001).floor() as usize;
        assert_eq!(applied, expected, "a command {arrival_age} s old at arrival");
    }
    // Stamped in the future: it answers no joint state yet measured.
    for ahead in [-0.019, -0.001] {
        assert!(matches!(
            d.set_remote_command(&[5.0; 7], s, NOW - ahead, NOW, CONTROLLER, || 1),
            Err(DriverError::TooOld(..))
        ));
    }
    // A gap between measurements (the KRC or the link stalled): by the driver's clock the command taken
    // 12 ms old before it is 30 ms old after it, though one cycle has passed.
    d.set_remote_command(&[5.0; 7], s, NOW - 0.012, NOW, CONTROLLER, || 1).unwrap();
    d.expire_command(NOW + 0.007);
    let seq = 2 + d.counters.measurements as u16;
    assert!(!d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().1.holding);
    d.expire_command(NOW + 0.018);
    let seq = 2 + d.counters.measurements as u16;
    assert!(d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().1.holding);
    // The in-process controller's own command (age 0) is applied for the whole watchdog, and never
    // expired by a clock: it answers the very measurement.
    d.set_command(&[5.0; 7]).unwrap();
    d.expire_command(NOW + 1000.0);
    let held = (0..5)
        .filter(|_| {
            let seq = 2 + d.counters.measurements as u16;
            d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().1.holding
        })
        .count();
    assert_eq!(held, 0);
}

#[test]
fn implausible_measurements_are_refused_unanswered() {
    // Safety class 8: sample time +inf disabled the overspeed guard; positions of 1e30 became the hold.
    let mut d = LwrDriver::new(DriverParams::default());
    let tweak = |f: &dyn Fn(&mut fri::Measurement)| {
        let mut m = fri::Measurement::decode(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
        f(&mut m);
        m.encode().to_vec()
    };
    let bad = [
        tweak(&|m| m.intf.desired_msr_sample_time = f32::INFINITY),
        tweak(&|m| m.intf.desired_msr_sample_time = 1e9),
        tweak(&|m| m.intf.desired_msr_sample_time = 0.0),
        tweak(&|m| m.intf.desired_msr_sample_time = -0.001),
        tweak(&|m| m.data.msr_jnt_pos[3] = 1e30),
        tweak(&|m| m.data.msr_jnt_pos[0] = -3.2),
        tweak(&|m| m.data.gravity[1] = 1e9),
    ];
    for (i, datagram) in bad.iter().enumerate() {
        // Some are refused by the decoder (non-finite control data), the rest by the driver.
        assert!(d.handle(datagram).is_err(), "case {i}");
    }
    assert_eq!(d.counters.measurements, 0);
    assert_eq!(d.counters.implausible + d.counters.malformed, bad.len() as u64);
    assert!(d.handle(&measurement(1, InterfaceState::Command, Q, G)).is_ok());
}

#[test]
fn torques_beyond_the_joint_limits_are_refused_and_the_driver_holds() {
    // Adversary, separate layout: 1e300 and 1e6 N·m were clipped to the limits and applied.
    for (joint, bad) in [(0, 176.01), (1, -1e6), (6, 1e300), (4, -100.5)] {
        let mut d = LwrDriver::new(DriverParams::default());
        d.handle(&measurement(1, InterfaceState::Command, Q, [0.0; 7])).unwrap();
        d.set_command(&[5.0; 7]).unwrap();
        let mut tau = [0.0; 7];
        tau[joint] = bad;
        assert!(matches!(d.set_command(&tau), Err(DriverError::BeyondLimit(j, ..)) if j == joint), "{bad}");
        let (reply, out) = d.handle(&measurement(2, InterfaceState::Command, Q, [0.0; 7])).unwrap();
        assert!(out.holding && reply.add_jnt_trq == [0.0; 7], "no torque of either command: {:?}", reply.add_jnt_trq);
    }
    // At the limit is a command.
    let mut d = LwrDriver::new(DriverParams::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, [0.0; 7])).unwrap();
    d.set_command(&[176.0, -176.0, 100.0, -100.0, 100.0, 38.0, -38.0]).unwrap();
    let (reply, _) = d.handle(&measurement(2, InterfaceState::Command, Q, [0.0; 7])).unwrap();
    assert_eq!((reply.add_jnt_trq[0], reply.add_jnt_trq[6]), (176.0, -38.0));
}

#[test]
fn only_the_pinned_writer_commands_for_the_session() {
    // Adversary, separate layout: a stranger's commands, with stamp and session copied from the live
    // joint states, were all accepted.
    let mut d = LwrDriver::new(DriverParams::default());
    d.accept_sender("127.0.0.1:40000".parse().unwrap(), f64::INFINITY);
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    let s = Some(d.session());
    // Two writers and none pinned: neither commands.
    assert!(matches!(
        d.set_remote_command(&[5.0; 7], s, NOW - 0.001, NOW, STRANGER, || 2),
        Err(DriverError::Writer(WriterRefused::Ambiguous(2)))
    ));
    d.set_remote_command(&G.map(f64::from), s, NOW - 0.001, NOW, CONTROLLER, || 1).unwrap();
    // The stranger's command, well formed and in time, touches nothing: the controller's stays.
    let err = d.set_remote_command(&[50.0; 7], s, NOW - 0.001, NOW, STRANGER, || 2).unwrap_err();
    assert_eq!(err, DriverError::Writer(WriterRefused::Stranger));
    let (reply, out) = d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap();
    assert!(!out.holding && reply.add_jnt_trq == [0.0; 7], "the controller's gravity torque: {:?}", reply.add_jnt_trq);
    // Nor can a stranger's NaN make the driver hold.
    assert!(d.set_remote_command(&[f64::NAN; 7], s, NOW - 0.001, NOW, STRANGER, || 2).is_err());
    assert!(!d.handle(&measurement(3, InterfaceState::Command, Q, G)).unwrap().1.holding);
    assert_eq!((d.counters.commands_from_strangers, d.counters.commands_refused), (3, 0));
    // A new KRC session releases the pin: the sole writer then is pinned.
    d.begin_session();
    let s = Some(d.session());
    d.set_remote_command(&[5.0; 7], s, NOW - 0.001, NOW, STRANGER, || 1).unwrap();
    assert!(d.set_remote_command(&[5.0; 7], s, NOW - 0.001, NOW, CONTROLLER, || 2).is_err());
}

/// Measurements of joint `joint` moving from `from` at `speed` [rad/s] (1 ms apart), the driver applying
/// `torque` (total) whenever it does not hold; the cycle of the first hold and the driver.
fn drive(joint: usize, from: f32, speed: f32, cycles: u16, config: DriverParams) -> (Option<u16>, LwrDriver) {
    let mut d = LwrDriver::new(config);
    let mut first_hold = None;
    for k in 1..=cycles {
        let mut q = Q;
        q[joint] = from + speed * 1e-3 * k as f32;
        d.set_command(&G.map(f64::from)).unwrap();
        let (reply, out) = d.handle(&measurement(k, InterfaceState::Command, q, G)).unwrap();
        if out.holding && first_hold.is_none() {
            first_hold = Some(k);
            assert_eq!(reply.add_jnt_trq, [0.0; 7], "a fault keeps no torque");
            assert!(reply.jnt_pos[joint] <= 2.0944, "never held beyond the limit: {}", reply.jnt_pos[joint]);
        }
    }
    (first_hold, d)
}

#[test]
fn a_joint_heading_into_its_position_limit_holds_the_arm_until_the_operator_restarts_the_krl_program() {
    // Adversary, separate layout: +8 N·m on joint 5 carried it 0.1 rad past its limit while the driver
    // applied every command (it only stopped answering once the measurement was implausible).
    let upper = 2.0944; // joint 4, ±120°
    let margin = DriverParams::default().limit_margin;
    // At 1 rad/s from 1.7 rad: the band begins at 1.9944 rad, seen 50 ms (0.05 rad) ahead, i.e. from
    // 1.9444 rad, reached after 244 ms.
    let (first, d) = drive(3, 1.7, 1.0, 400, DriverParams::default());
    let expected = ((upper - margin - 0.05 - 1.7) / 1e-3_f64).ceil() as u16;
    assert!(first.is_some_and(|k| k.abs_diff(expected) <= 1), "first hold {first:?}, expected {expected}");
    assert!(matches!(d.fault(), Some(Fault::PositionLimit { joint: 4, .. })), "{:?}", d.fault());
    assert!(d.counters.limit_cycles >= 150, "held on, fresh commands or not: {}", d.counters.limit_cycles);
    // Slowly, the band itself.
    // Slowly (0.1 rad/s, 5 mrad ahead) from 1.98 rad: at 1.9894 rad, after 94 ms.
    let (first, _) = drive(3, 1.98, 0.1, 200, DriverParams::default());
    assert!(first.is_some_and(|k| (93..=95).contains(&k)), "{first:?}");
    // Away from the limit: never.
    let (first, d) = drive(3, 1.7, -1.0, 400, DriverParams::default());
    assert_eq!((first, d.fault()), (None, None));
    // The fault stands through new sessions, silences and the KRC's own fallback to monitor mode, until
    // the operator restarts the KRL program.
    let (_, mut d) = drive(3, 1.99, 0.0, 10, DriverParams::default());
    d.set_command(&G.map(f64::from)).unwrap();
    assert!(d.handle(&measurement(11, InterfaceState::Command, Q, G)).unwrap().1.holding, "back inside, still held");
    d.begin_session();
    d.resumed_after(5.0);
    let mut stopped = fri::Measurement::decode(&measurement(1, InterfaceState::Monitor, Q, G)).unwrap();
    stopped.krl.int[1] = 0;
    let (reply, out) = d.handle(&stopped.encode()).unwrap();
    assert_eq!(reply.krl.int[1], 0, "no start asked for while the fault stands");
    assert!(matches!(out.waiting, Some(Waiting::Fault(_))));
    d.set_command(&G.map(f64::from)).unwrap();
    assert!(d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap().1.holding, "a new session holds on");
    assert!(d.fault().is_some());
    // A datagram or a few saying the program just began, or saying so with FRI off, are no restart.
    stopped.krl.int[1] = 10;
    stopped.intf.state = InterfaceState::Off;
    for seq in 3..300 {
        stopped.header.send_seq = seq;
        d.handle(&stopped.encode()).unwrap();
    }
    stopped.intf.state = InterfaceState::Monitor;
    for seq in 300..399 {
        stopped.header.send_seq = seq;
        d.handle(&stopped.encode()).unwrap();
    }
    d.handle(&measurement(399, InterfaceState::Command, Q, G)).unwrap();
    assert!(d.fault().is_some(), "99 measurements of a restarted program");
    for seq in 400..499 {
        stopped.header.send_seq = seq;
        d.handle(&stopped.encode()).unwrap();
    }
    stopped.header.send_seq = 499;
    let (reply, out) = d.handle(&stopped.encode()).unwrap();
    assert_eq!((d.fault(), out.waiting, reply.krl.int[1]), (None, Some(Waiting::Monitor(InterfaceState::Monitor)), 1));
    d.handle(&measurement(500, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&G.map(f64::from)).unwrap();
    assert!(!d.handle(&measurement(501, InterfaceState::Command, Q, G)).unwrap().1.holding);
    assert_eq!(d.counters.faults_cleared, 1);
}

#[test]
fn no_fresh_command_means_holding_position() {
    let mut d = LwrDriver::new(DriverParams::default());
    let (reply, out) = d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    assert!(out.holding, "no command yet");
    assert_eq!(reply.jnt_pos, Q);
    assert!(reply.jnt_stiffness.iter().all(|k| *k > 0.0) && reply.add_jnt_trq == [0.0; 7]);
    d.set_command(&[0.0; 7]).unwrap();
    // Set after measurement 1, the command is 1 cycle old at measurement 2 and 5 cycles old at 6.
    for seq in 2..=6 {
        let (_, out) = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap();
        assert!(!out.holding, "fresh for the watchdog's 5 cycles (cycle {seq})");
    }
    let (_, out) = d.handle(&measurement(7, InterfaceState::Command, Q, G)).unwrap();
    assert!(out.holding, "stale when older than 5 cycles");
}

#[test]
fn a_hold_for_a_stale_command_hands_its_torque_to_the_spring_and_overspeed_drops_it() {
    let config = DriverParams { hold_release_cycles: 100, ..DriverParams::default() };
    let (k, limit) = (config.hold_stiffness, config.hold_max_preload);
    let mut d = LwrDriver::new(config.clone());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    // Joints 2 and 4 need more than the preload can carry (3000 × 0.05 = 150 N·m, 1500 × 0.05 = 75 N·m).
    let total = [1.0, 170.0, 0.5, -95.0, -0.2, 1.0, 0.3];
    d.set_command(&total).unwrap();
    let beyond_gravity: [f64; 7] = std::array::from_fn(|i| total[i] - G[i] as f64);
    let mut seq = 2;
    let mut reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    // What the hold applies at the held position: its spring's preload and the torque added.
    let applied = |r: &softcontact_wire::fri::Command, i: usize| {
        r.jnt_stiffness[i] as f64 * (r.jnt_pos[i] as f64 - Q[i] as f64) + r.add_jnt_trq[i] as f64
    };
    // Stale from cycle 7 on: held at the position of the first stale cycle.
    while seq < 7 {
        seq += 1;
        reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    }
    assert!(reply.jnt_stiffness.iter().all(|kj| *kj > 0.0), "holding");
    for (i, full) in beyond_gravity.iter().enumerate() {
        let offset = reply.jnt_pos[i] as f64 - Q[i] as f64;
        assert!(offset.abs() <= limit * (1.0 + 1e-5), "joint {i}: set point {offset} rad off, limit {limit}");
        let kept = applied(&reply, i);
        assert!((kept - full).abs() < 2e-3 * full.abs().max(1.0), "first cycle keeps all of {full}: {kept}");
    }
    for _ in 0..50 {
        seq += 1;
        reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    }
    for (i, full) in beyond_gravity.iter().enumerate() {
        let carried = (full / k[i]).clamp(-limit, limit) * k[i];
        let expected = carried + 0.5 * (full - carried);
        let kept = applied(&reply, i);
        assert!(
            (kept - expected).abs() < 2e-3 * full.abs().max(1.0),
            "joint {i}: half the rest fades: {kept} vs {expected}"
        );
    }
    for _ in 0..60 {
        seq += 1;
        reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    }
    assert_eq!(reply.add_jnt_trq, [0.0; 7], "the rest released");
    for (i, full) in beyond_gravity.iter().enumerate() {
        let carried = (full / k[i]).clamp(-limit, limit) * k[i];
        assert!((applied(&reply, i) - carried).abs() < 2e-3 * full.abs().max(1.0), "joint {i}: the spring carries on");
    }

    // Overspeed: the command is suspect, its torque and any preload go at once.
    let mut d = LwrDriver::new(config);
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&total).unwrap();
    d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap();
    let mut fast = Q;
    fast[6] += 0.0031;
    let (reply, out) = d.handle(&measurement(3, InterfaceState::Command, fast, G)).unwrap();
    assert!(out.holding);
    assert_eq!(reply.add_jnt_trq, [0.0; 7]);
    assert_eq!(reply.jnt_pos, Q, "held where the arm was before the jump, no preload");
}

#[test]
fn a_joint_too_fast_makes_the_driver_hold() {
    let mut d = LwrDriver::new(DriverParams::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&[0.0; 7]).unwrap();
    let mut fast = Q;
    fast[6] += 0.0031; // 3.1 rad/s over 1 ms; the limit is 3.21 rad/s, the margin 90 %
    // Read, the measurement already says: no torque mode — a controller given it integrates nothing.
    let measured = d.measure(&measurement(2, InterfaceState::Command, fast, G)).unwrap();
    assert!(matches!(measured.output.waiting, Some(Waiting::Fault(Fault::Overspeed { joint: 7, .. }))));
    assert!(!measured.output.torque_mode());
    let (reply, out) = d.answer(measured);
    assert_eq!(reply.add_jnt_trq, [0.0; 7]);
    assert!(out.holding && d.counters.overspeed_cycles == 1);
    assert!((out.dq[6] - 3.1).abs() < 1e-3);
    // A fault: held on, fresh commands and a still joint or not, until the KRC starts a new session.
    for seq in 3..10 {
        d.set_command(&[0.0; 7]).unwrap();
        assert!(d.handle(&measurement(seq, InterfaceState::Command, fast, G)).unwrap().1.holding);
    }
    assert!(matches!(d.fault(), Some(Fault::Overspeed { joint: 7, .. })));
}

#[test]
fn lost_and_repeated_measurements_are_counted() {
    let mut d = LwrDriver::new(DriverParams::default());
    for seq in [65534u16, 65535, 2, 2, 3] {
        d.handle(&measurement(seq, InterfaceState::Monitor, Q, G)).unwrap();
    }
    assert_eq!((d.counters.lost, d.counters.out_of_order, d.counters.measurements), (2, 1, 5));
    assert!(d.handle(b"garbage").is_err());
    assert_eq!(d.counters.malformed, 1);
}

#[test]
fn butterworth_low_pass_has_unit_dc_gain_and_minus_3_db_at_the_cutoff() {
    let (fs, fc) = (1000.0, 50.0);
    let gain = |f: f64| {
        let mut lp = Biquad::low_pass(fc, fs).unwrap();
        let mut peak: f64 = 0.0;
        for n in 0..20_000 {
            let y = lp.filter((2.0 * std::f64::consts::PI * f * n as f64 / fs).sin());
            if n > 10_000 {
                peak = peak.max(y.abs());
            }
        }
        peak
    };
    let mut lp = Biquad::low_pass(fc, fs).unwrap();
    let dc = (0..2000).map(|_| lp.filter(3.0)).last().unwrap();
    assert!((dc - 3.0).abs() < 1e-12, "DC gain 1: {dc}");
    assert!((gain(fc) - std::f64::consts::FRAC_1_SQRT_2).abs() < 2e-3, "−3 dB at the cut-off: {}", gain(fc));
    assert!(gain(200.0) < 0.07, "strong attenuation above: {}", gain(200.0));
    assert!(Biquad::low_pass(600.0, fs).is_err());
}

#[test]
fn the_ft_node_removes_bias_and_tool_weight() {
    let config = FtConfig {
        calibration: Calibration::gamma_si_130_10(),
        tool: lwr4::tool_load(),
        gravity: Vector3::new(0.0, 0.0, -9.81),
        low_pass: None,
        sample_rate: 1000.0,
    };
    let mut node = FtSensorNode::new(config).unwrap();
    // Hand facing down (sensor z down): the hand's 0.2 kg reads +1.962 N along z; the box adds a bias.
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let counts = |f: [f64; 6]| Calibration::gamma_si_130_10().to_counts(&f).0;
    let weight = 0.2 * 9.81;
    let bias = [0.4, -0.3, 0.8, 0.01, -0.02, 0.005];
    let rec = |seq: u32, ext_z: f64| {
        let w = [bias[0], bias[1], bias[2] + weight + ext_z, bias[3], bias[4], bias[5]];
        Record { rdt_sequence: seq, ft_sequence: seq, status: Status(0), counts: counts(w) }.encode()
    };
    node.handle(&rec(0, 0.0), Some(&down)).unwrap();
    node.tare(Some(&down)).unwrap();
    let out = node.handle(&rec(1, -25.0), Some(&down)).unwrap();
    let c = out.compensated.unwrap();
    assert!((c[2] + 25.0).abs() < 1e-5 && c[0].abs() < 1e-5, "{c:?}");
    assert!((out.raw[2] - (weight - 25.0)).abs() < 1e-5, "raw keeps the tool's weight: {:?}", out.raw);
    let saturated = Record { rdt_sequence: 2, status: Status(0x8002_0000), ..Default::default() }.encode();
    assert!(node.handle(&saturated, None).unwrap().invalid);
    node.handle(&rec(5, 0.0), None).unwrap();
    assert_eq!((node.counters.lost, node.counters.saturated), (2, 1));
}

#[test]
fn datagrams_all_refused_are_told_apart_from_some_refused() {
    let mut d = LwrDriver::new(DriverParams::default());
    let before = d.counters;
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    let accepted = d.counters;
    assert_eq!(accepted.refusals_since(&before).refused(), 0);
    // A joint far beyond its limit: implausible, refused unanswered.
    let mut wild = Q;
    wild[3] = 40.0;
    for seq in 2..12 {
        assert!(d.handle(&measurement(seq, InterfaceState::Command, wild, G)).is_err());
    }
    assert!(d.handle(&[0u8; 3]).is_err());
    let only_refused = d.counters.refusals_since(&accepted);
    assert!(only_refused.all_refused(), "{only_refused}");
    assert_eq!((only_refused.implausible, only_refused.malformed), (10, 1));
    let some = d.counters.refusals_since(&before);
    assert!(!some.all_refused() && some.refused() == 11 && some.accepted == 1, "{some}");
}

/// A measurement in command state with the KRC's robot and KRL fields set by `edit`.
fn commanding_with(seq: u16, edit: impl FnOnce(&mut fri::Measurement)) -> Vec<u8> {
    let mut m = fri::Measurement::decode(&measurement(seq, InterfaceState::Command, Q, G)).unwrap();
    m.data.msr_cart_pos = std::array::from_fn(|i| 0.1 * i as f32);
    edit(&mut m);
    m.encode().to_vec()
}

#[test]
fn a_krc_commanding_in_position_control_gets_the_measured_position_and_no_torque() {
    let mut d = LwrDriver::new(DriverParams::default());
    for seq in 1..2000u16 {
        let (reply, out) = d
            .handle(&commanding_with(seq, |m| {
                m.robot.control = fri::ControlMode::Position;
                m.krl.int[0] = 10;
            }))
            .unwrap();
        // A controller's torque, however fresh, never reaches the arm.
        d.set_command(&[5.0, 60.0, 1.0, -20.0, 1.0, 2.0, 0.5]).unwrap();
        assert_eq!(reply.add_jnt_trq, [0.0; 7]);
        assert_eq!(reply.add_tcp_ft, [0.0; 6]);
        assert_eq!(reply.jnt_pos, Q, "position control holds the measured position");
        assert_eq!(reply.krl.int[1], 0, "the KRL program is asked to stop, to start again in joint impedance");
        assert_eq!(out.waiting, Some(Waiting::Strategy(fri::ControlMode::Position)));
        assert!(!out.torque_mode() && out.holding);
    }
    assert_eq!(d.counters.waiting_cycles, 1999);
    assert!(Waiting::Strategy(fri::ControlMode::Position).to_string().contains("asking the KRL program to stop"));
}

#[test]
fn in_every_other_mode_the_answer_is_that_modes_safe_command_without_torque() {
    type Edit = fn(&mut fri::Measurement);
    type Expected = fn(&Waiting) -> bool;
    let cases: [(&str, Edit, Expected); 8] = [
        (
            "Cartesian impedance",
            |m| m.robot.control = fri::ControlMode::CartesianImpedance,
            |w| matches!(w, Waiting::Strategy(fri::ControlMode::CartesianImpedance)),
        ),
        ("another strategy", |m| m.robot.control = fri::ControlMode::Other, |w| matches!(w, Waiting::Strategy(_))),
        ("not started", |m| m.krl.int[1] = 10, |w| matches!(w, Waiting::Handshake { started: 10, .. })),
        ("another strategy reported", |m| m.krl.int[0] = 10, |w| matches!(w, Waiting::Handshake { strategy: 10, .. })),
        ("one drive off", |m| m.robot.power = 0x7E, |w| matches!(w, Waiting::DrivesOff(0x7E))),
        ("a drive error", |m| m.robot.error = 0x20, |w| matches!(w, Waiting::DriveError(0x20))),
        ("quality bad", |m| m.intf.quality = Quality::Bad, |w| matches!(w, Waiting::Quality(Quality::Bad))),
        (
            "quality unacceptable",
            |m| m.intf.quality = Quality::Unacceptable,
            |w| matches!(w, Waiting::Quality(Quality::Unacceptable)),
        ),
    ];
    for (what, edit, expected) in cases {
        let mut d = LwrDriver::new(DriverParams::default());
        // Torque mode first, a command applied: then the KRC changes.
        d.handle(&commanding_with(1, |_| {})).unwrap();
        d.set_command(&[5.0, 60.0, 1.0, -20.0, 1.0, 2.0, 0.5]).unwrap();
        assert!(!d.handle(&commanding_with(2, |_| {})).unwrap().1.holding);
        for seq in 3..600u16 {
            d.set_command(&[5.0, 60.0, 1.0, -20.0, 1.0, 2.0, 0.5]).unwrap();
            let (reply, out) = d.handle(&commanding_with(seq, edit)).unwrap();
            assert!(out.waiting.as_ref().is_some_and(expected), "{what}: {:?}", out.waiting);
            assert!(!out.torque_mode() && out.holding, "{what}");
            assert_eq!(reply.add_jnt_trq, [0.0; 7], "{what}: no added torque");
            assert_eq!(reply.add_tcp_ft, [0.0; 6], "{what}: no added force");
            assert_eq!(reply.cart_pos, std::array::from_fn(|i| 0.1 * i as f32), "{what}: the measured pose");
            assert_eq!(reply.flags, flags::JOINT_IMPEDANCE, "{what}: flags never change in command mode");
            for (i, (sent, measured)) in reply.jnt_pos.iter().zip(Q).enumerate() {
                let preload = DriverParams::default().hold_max_preload as f32;
                assert!(
                    (sent - measured).abs() <= preload + 1e-6,
                    "{what}: joint {i} held at {sent}, is at {measured}"
                );
            }
        }
    }
}

#[test]
fn torque_mode_beginning_again_is_a_new_session_and_no_earlier_command_is_applied() {
    let mut d = LwrDriver::new(DriverParams::default());
    d.handle(&commanding_with(1, |_| {})).unwrap();
    let first = d.session();
    d.set_command(&[5.0, 60.0, 1.0, -20.0, 1.0, 2.0, 0.5]).unwrap();
    d.handle(&commanding_with(2, |m| m.robot.control = fri::ControlMode::Position)).unwrap();
    let (reply, out) = d.handle(&commanding_with(3, |_| {})).unwrap();
    assert_ne!(out.session, first, "back in joint impedance: a new session");
    assert!(out.torque_mode() && out.holding, "the command of before is gone: hold until one answers");
    assert_eq!(reply.add_jnt_trq, [0.0; 7]);
    // A network controller's command answering the old session is refused.
    let old = d.set_remote_command(&[0.0; 7], Some(first), NOW, NOW, CONTROLLER, || 1);
    assert!(matches!(old, Err(DriverError::OtherSession(..))), "{old:?}");
}
