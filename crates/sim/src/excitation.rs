//! A free-space excitation of the simulated arm: each joint follows its own sine about the start under a
//! joint PD, and the run is recorded as the product would see it — the joint state of each cycle and the
//! total joint torque commanded for it (the URDF's gravity plus the PD's, as /lwr/joint_torque_command
//! carries it). What the arm's own effects are identified from; whatever `SimConfig` hides (friction, a
//! payload) stays in the physics.

use softcontact_dynamics::lwr4;
use softcontact_wire::fri::{self, InterfaceState, Quality, flags};

use crate::{SimConfig, SimError, Simulator};

/// One cycle of the run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExcitationSample {
    pub t: f64,
    pub q: [f64; 7],
    pub dq: [f64; 7],
    /// Total joint torque commanded [N m], gravity included.
    pub tau: [f64; 7],
}

/// The sines' frequencies [Hz] (incommensurate, so that the joints' motions do not repeat together),
/// amplitude [rad] and the PD's stiffness per joint [N m/rad] (damping a twentieth of it, in seconds):
/// stiff where the arm is heavy, soft at the light wrist, whose explicit 1 kHz loop a stiffer one would
/// destabilise.
const FREQUENCIES: [f64; 7] = [0.23, 0.31, 0.37, 0.43, 0.53, 0.61, 0.71];
const AMPLITUDE: f64 = 0.3;
const STIFFNESS: [f64; 7] = [300.0, 300.0, 150.0, 150.0, 20.0, 10.0, 5.0];

fn answer(m: &fri::Measurement, seq: u16, start: bool, torque: [f64; 7]) -> fri::Command {
    let mut c = fri::Command::default();
    c.header.send_seq = seq;
    c.header.refl_seq = m.header.send_seq;
    c.krl.int[0] = 30;
    c.krl.int[1] = i32::from(start);
    c.flags = flags::JOINT_IMPEDANCE;
    c.jnt_pos = m.data.msr_jnt_pos;
    c.add_jnt_trq = torque.map(|t| t as f32);
    c
}

/// Runs the excitation for `seconds` on the arm `config` describes (its surface, if any, should be out
/// of reach). Fails if the KRC leaves command mode.
pub fn excite(config: SimConfig, seconds: f64) -> Result<Vec<ExcitationSample>, SimError> {
    let cycle = config.cycle;
    let model = lwr4::model();
    let mut data = model.data();
    let mut sim = Simulator::new(config)?;
    let mut seq = 0u16;
    for _ in 0..1000 {
        if sim.krc.state() == InterfaceState::Command {
            break;
        }
        let m = sim.measurement();
        seq = seq.wrapping_add(1);
        sim.command(&answer(&m, seq, m.intf.quality == Quality::Perfect, [0.0; 7]));
        sim.step_cycle()?;
    }
    let q0 = *sim.q();
    let mut out = Vec::new();
    for i in 0..(seconds / cycle).round() as usize {
        let t = i as f64 * cycle;
        if sim.krc.state() != InterfaceState::Command {
            return Err(SimError::Config(format!("the KRC left command mode at {t} s: {:?}", sim.krc.last_fault())));
        }
        let m = sim.measurement();
        let (q, dq) = (*sim.q(), *sim.dq());
        let pd: [f64; 7] = std::array::from_fn(|j| {
            let w = std::f64::consts::TAU * FREQUENCIES[j];
            let (target, rate) = (q0[j] + AMPLITUDE * (w * t).sin(), AMPLITUDE * w * (w * t).cos());
            STIFFNESS[j] * (target - q[j]) + 0.05 * STIFFNESS[j] * (rate - dq[j])
        });
        let g = model.gravity_torques(&mut data, &q);
        out.push(ExcitationSample { t, q, dq, tau: std::array::from_fn(|j| g[j] + pd[j]) });
        seq = seq.wrapping_add(1);
        sim.command(&answer(&m, seq, true, pd));
        sim.step_cycle()?;
    }
    Ok(out)
}
