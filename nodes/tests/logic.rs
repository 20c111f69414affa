//! The nodes' logic without sockets: driver replies and the F/T node's arithmetic.

use nalgebra::{UnitQuaternion, Vector3};
use softcontact_dynamics::lwr4;
use softcontact_nodes::ft_sensor::{Biquad, FtConfig, FtSensorNode};
use softcontact_nodes::lwr_driver::{DriverConfig, DriverError, LwrDriver};
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
    m.data.msr_jnt_pos = q;
    m.data.cmd_jnt_pos = q;
    m.data.cmd_jnt_pos_fri_offset[0] = 0.001;
    m.data.gravity = gravity;
    m.encode().to_vec()
}

const Q: [f32; 7] = [0.0, 0.5, 0.0, -1.4, 0.0, 1.2, 0.0];
const G: [f32; 7] = [0.0, -30.0, 0.5, 10.0, -0.2, 0.9, 0.0];

#[test]
fn in_command_mode_the_krc_gravity_is_removed_from_the_total_torque() {
    let mut d = LwrDriver::new(DriverConfig::default());
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
    let mut d = LwrDriver::new(DriverConfig::default());
    let (reply, _) = d.handle(&measurement(1, InterfaceState::Monitor, Q, G)).unwrap();
    assert!((reply.jnt_pos[0] - 0.001).abs() < 1e-7, "cmdJntPos + cmdJntPosFriOffset");
    assert_eq!(reply.add_jnt_trq, [0.0; 7]);
    assert_eq!((reply.krl.int[0], reply.krl.int[1]), (30, 1));
}

#[test]
fn bad_commands_are_refused_and_the_last_good_one_kept() {
    let mut d = LwrDriver::new(DriverConfig::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&[0.0; 7]).unwrap();
    assert_eq!(d.set_command(&[0.0; 6]), Err(DriverError::CommandLength(6)));
    assert_eq!(d.set_command(&[0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]), Err(DriverError::NonFiniteCommand(2)));
    let (reply, _) = d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap();
    assert!((reply.add_jnt_trq[1] - 30.0).abs() < 1e-5, "zero total torque, less gravity");
    assert_eq!(d.counters.commands_refused, 2);
}

#[test]
fn torques_are_clipped_to_the_joint_limits() {
    let mut d = LwrDriver::new(DriverConfig::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, [0.0; 7])).unwrap();
    d.set_command(&[500.0, -500.0, 0.0, 0.0, 0.0, 0.0, 50.0]).unwrap();
    let (reply, _) = d.handle(&measurement(2, InterfaceState::Command, Q, [0.0; 7])).unwrap();
    assert_eq!((reply.add_jnt_trq[0], reply.add_jnt_trq[1], reply.add_jnt_trq[6]), (176.0, -176.0, 38.0));
    assert_eq!(d.counters.clipped_cycles, 1);
}

#[test]
fn no_fresh_command_means_holding_position() {
    let mut d = LwrDriver::new(DriverConfig::default());
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
fn a_hold_for_a_stale_command_fades_its_torque_out_and_overspeed_drops_it() {
    let config = DriverConfig { hold_release_cycles: 100, ..DriverConfig::default() };
    let mut d = LwrDriver::new(config.clone());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    let total = [1.0, 50.0, 0.5, -40.0, -0.2, 1.0, 0.3];
    d.set_command(&total).unwrap();
    let beyond_gravity: [f32; 7] = std::array::from_fn(|i| total[i] as f32 - G[i]);
    let mut seq = 2;
    let mut reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    // Stale from cycle 7 on: held at the position of the first stale cycle, the torque fading linearly.
    while seq < 7 {
        seq += 1;
        reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    }
    assert_eq!(reply.jnt_pos, Q);
    assert!(reply.jnt_stiffness.iter().all(|k| *k > 0.0), "holding");
    for (sent, full) in reply.add_jnt_trq.iter().zip(beyond_gravity) {
        assert!((sent - full).abs() < 1e-4, "the first cycle of the hold keeps the whole torque: {sent} vs {full}");
    }
    for _ in 0..50 {
        seq += 1;
        reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    }
    for (sent, full) in reply.add_jnt_trq.iter().zip(beyond_gravity) {
        assert!((sent - 0.5 * full).abs() < 1e-4, "half of {full} after half the release: {sent}");
    }
    for _ in 0..60 {
        seq += 1;
        reply = d.handle(&measurement(seq, InterfaceState::Command, Q, G)).unwrap().0;
    }
    assert_eq!(reply.add_jnt_trq, [0.0; 7], "released");

    // Overspeed: the command is suspect, its torque goes at once.
    let mut d = LwrDriver::new(config);
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&total).unwrap();
    d.handle(&measurement(2, InterfaceState::Command, Q, G)).unwrap();
    let mut fast = Q;
    fast[6] += 0.0031;
    let (reply, out) = d.handle(&measurement(3, InterfaceState::Command, fast, G)).unwrap();
    assert!(out.holding);
    assert_eq!(reply.add_jnt_trq, [0.0; 7]);
}

#[test]
fn a_joint_too_fast_makes_the_driver_hold() {
    let mut d = LwrDriver::new(DriverConfig::default());
    d.handle(&measurement(1, InterfaceState::Command, Q, G)).unwrap();
    d.set_command(&[0.0; 7]).unwrap();
    let mut fast = Q;
    fast[6] += 0.0031; // 3.1 rad/s over 1 ms; the limit is 3.21 rad/s, the margin 90 %
    let (_, out) = d.handle(&measurement(2, InterfaceState::Command, fast, G)).unwrap();
    assert!(out.holding && d.counters.overspeed_cycles == 1);
    assert!((out.dq[6] - 3.1).abs() < 1e-3);
}

#[test]
fn lost_and_repeated_measurements_are_counted() {
    let mut d = LwrDriver::new(DriverConfig::default());
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
