//! The arm's own effects in the demo: the simulated LWR carries joint friction and a flange payload its
//! URDF does not know (hidden in the simulator's physics). The discrepancy workflow names them from a
//! free-space excitation (joint states and the torques commanded for them), writes the controller's
//! compensation overlay, and one cycle of the force-control paper's force commands on the sponge is run without and with
//! the compensation: how closely the hand follows the deformation reference, how still it holds across
//! the surface, and the force at the end of each move.

use std::path::{Path, PathBuf};

use anyhow::Context;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use softcontact_discrepancy::{ArmOptions, ArmSample, name_arm_effects};
use softcontact_dynamics::{ArmEffects, JointFriction, Payload, lwr4};
use softcontact_nodes::contact_estimator::{ContactEstimatorNode, EstimatorConfig};
use softcontact_nodes::deformation_controller::{ControllerConfig, DeformationController};
use softcontact_sim::{FtSensorConfig, SimConfig};
use softcontact_simcell::cell::Cell;

use super::experiment::{RATIOS, SurfaceSpec};

/// What the simulated arm hides: friction of the size the LWR's joints have, and 1.2 kg on the flange.
pub fn hidden() -> ArmEffects {
    ArmEffects {
        joint_friction: Some(JointFriction {
            viscous: [0.8, 0.8, 0.5, 0.5, 0.3, 0.2, 0.2],
            coulomb: [0.5, 0.5, 0.25, 0.25, 0.2, 0.05, 0.05],
        }),
        payload: Some(Payload { mass: 1.2, com: [0.01, -0.02, 0.03] }),
    }
}

/// Seconds of the free-space excitation the effects are named from.
const EXCITATION: f64 = 10.0;

/// How the hand followed its references over one cycle of force commands.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Tracking {
    /// RMS of the deformation's distance from its reference \[m\].
    pub deformation_rms: f64,
    /// RMS of the hand's distance across the surface from where it is held \[m\].
    pub lateral_rms: f64,
    /// The largest |true force − command| / command at the end of a move.
    pub worst_force_error: f64,
}

/// The arm section of the demo's JSON.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ArmReport {
    pub hidden: ArmEffects,
    /// What the workflow named from the excitation.
    pub named: ArmEffects,
    pub named_ids: Vec<String>,
    /// Residual torque per joint before and after the named effects [N m, RMS].
    pub rms_before: [f64; 7],
    pub rms_after: [f64; 7],
    pub without_compensation: Tracking,
    pub with_compensation: Tracking,
    pub overlay_file: PathBuf,
}

/// Names the arm's hidden effects from a free-space excitation, writes the compensation overlay into
/// `out`, and runs one cycle of force commands on `spec`'s surface without and with it.
pub fn run(spec: &SurfaceSpec, seed: u64, out: &Path) -> anyhow::Result<ArmReport> {
    let hidden = hidden();
    let base = SimConfig::above_surface(spec.truth.clone(), seed);
    let arm = |sim: SimConfig| SimConfig { friction: hidden.joint_friction, payload: hidden.payload, ..sim };
    let free = SimConfig { surface: None, sensor: FtSensorConfig::ideal(), ..arm(base.clone()) };
    let samples: Vec<ArmSample> = softcontact_sim::excitation::excite(free, EXCITATION)?
        .iter()
        .map(|s| ArmSample { t: s.t, q: s.q, dq: s.dq, tau: s.tau })
        .collect();
    let report = name_arm_effects(&lwr4::model(), &samples, ArmOptions::default())?;
    let named = report.effects();
    let overlay_file = crate::arm_effects::write_overlay(&named, out)?;
    let mut tracking = [None; 2];
    for (slot, compensate) in tracking.iter_mut().zip([ArmEffects::default(), named]) {
        *slot = Some(press(spec, arm(base.clone()), compensate).context("the arm's tracking run")?);
    }
    let [Some(without_compensation), Some(with_compensation)] = tracking else { unreachable!() };
    Ok(ArmReport {
        hidden,
        named,
        named_ids: report.named.iter().map(|e| e.id().to_string()).collect(),
        rms_before: report.rms_before,
        rms_after: report.rms_after,
        without_compensation,
        with_compensation,
        overlay_file,
    })
}

/// One cycle of the force-control paper's first six commands (ratios of 80 % of the surface's force limit) through the
/// surface's true model, so that what is left is the arm's own tracking.
fn press(spec: &SurfaceSpec, sim: SimConfig, arm: ArmEffects) -> anyhow::Result<Tracking> {
    let surface = sim.surface.as_ref().context("a surface")?.point;
    let config = ControllerConfig { arm, ..ControllerConfig::lwr4(spec.max_force, spec.max_deformation) };
    let controller = DeformationController::new(config, spec.truth.clone())?;
    let mut cell = Cell::new(sim, controller, ContactEstimatorNode::new(EstimatorConfig::default())?)?;
    cell.start(5000)?;
    let mut waited = 0;
    while !cell.cycle()?.context("the KRC left command mode")?.controller.in_contact {
        waited += 1;
        anyhow::ensure!(waited < 20_000, "no contact after 20 s");
    }
    cell.controller.law.adopt_estimate(spec.truth.clone(), &surface, None)?;
    let normal = cell.controller.law.config().normal;
    let start = cell.lockstep.sim.tool_pose().translation.vector;
    let (mut deformation, mut lateral, mut n, mut worst) = (0.0, 0.0, 0.0, 0.0_f64);
    for ratio in RATIOS[0] {
        let command = ratio * 0.8 * spec.max_force;
        cell.controller.law.command_force(command, 2.0)?;
        for _ in 0..2000 {
            let tick = cell.cycle()?.context("the KRC left command mode")?;
            anyhow::ensure!(tick.refused.is_none(), "refused: {:?}", tick.refused);
            let c = &tick.controller;
            let away: Vector3<f64> = cell.lockstep.sim.tool_pose().translation.vector - start;
            deformation += (c.z - c.z_cmd).powi(2);
            lateral += (away - away.dot(&normal) * normal).norm_squared();
            n += 1.0;
        }
        worst = worst.max((cell.lockstep.sim.contact().normal_force - command).abs() / command);
    }
    Ok(Tracking {
        deformation_rms: (deformation / n).sqrt(),
        lateral_rms: (lateral / n).sqrt(),
        worst_force_error: worst,
    })
}

pub fn print(r: &ArmReport) {
    println!(
        "THE ARM'S OWN EFFECTS — named from {EXCITATION:.0} s of free-space motion (joint states and commanded torques, against the URDF)"
    );
    let friction = |e: &ArmEffects| {
        e.joint_friction.map_or("none".to_string(), |f| {
            format!(
                "viscous [{}] N m s/rad, Coulomb [{}] N m",
                f.viscous.map(|v| format!("{v:.2}")).join(" "),
                f.coulomb.map(|v| format!("{v:.2}")).join(" ")
            )
        })
    };
    let payload = |e: &ArmEffects| {
        e.payload.map_or("none".to_string(), |p| {
            format!("{:.3} kg at [{:.1}, {:.1}, {:.1}] mm", p.mass, p.com[0] * 1e3, p.com[1] * 1e3, p.com[2] * 1e3)
        })
    };
    println!("  named  {}", r.named_ids.join(", "));
    println!("  joint friction  named  {}\n                  hidden {}", friction(&r.named), friction(&r.hidden));
    println!("  flange payload  named  {}\n                  hidden {}", payload(&r.named), payload(&r.hidden));
    println!(
        "  residual torque [N m RMS], joints 1–7: {} → {}",
        r.rms_before.map(|v| format!("{v:.2}")).join(" "),
        r.rms_after.map(|v| format!("{v:.3}")).join(" ")
    );
    println!("  compensation overlay (--params-file of the deformation controller): {}", r.overlay_file.display());
    println!("  one cycle of force commands on the sponge, the arm's effects hidden in the simulator:");
    println!("  {:<22}{:>22}{:>22}{:>24}", "", "deformation tracking", "hold across surface", "force, end of move");
    for (label, t) in [("without compensation", &r.without_compensation), ("with compensation", &r.with_compensation)] {
        println!(
            "  {label:<22}{:>17.3} mm RMS{:>17.3} mm RMS{:>20.2} % worst",
            t.deformation_rms * 1e3,
            t.lateral_rms * 1e3,
            t.worst_force_error * 100.0
        );
    }
    println!();
}
