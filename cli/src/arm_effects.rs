//! `softcontact discrepancy --arm`: the arm's own effects (`crates/discrepancy/src/arm.rs`) named from a
//! recording of free-space motion — /lwr/joint_states (position, velocity) paired by stamp with the
//! /lwr/joint_torque_command that answered it (each command carries the stamp of its joint state).
//! Samples while the F/T sensor reads more than [`CONTACT`] are left out: a contact's torque is not the
//! arm's. The first [`MAX_SAMPLES`] free-space samples are analysed (20 s at 1 kHz, far more than the
//! 18 parameters need), so that memory stays bounded whatever the file.

use softcontact_msgs::topics;
use std::collections::BTreeMap;

use anyhow::Context;
use softcontact_bag::Recording;
use softcontact_discrepancy::{ArmEffect, ArmOptions, ArmReport, ArmSample, name_arm_effects};
use softcontact_dynamics::{ArmEffects, lwr4};
use softcontact_msgs::geometry_msgs::WrenchStamped;
use softcontact_msgs::sensor_msgs::JointState;

use crate::identify_cmd::WRENCH;

pub const JOINT_STATES: &str = topics::JOINT_STATES.name;
pub const TORQUE_COMMAND: &str = topics::JOINT_TORQUE_COMMAND.name;
/// A force reading above this means contact \[N\].
pub const CONTACT: f64 = 1.0;
/// The most samples analysed.
pub const MAX_SAMPLES: usize = 20_000;
/// Joint states waiting for their command are kept this long \[ns\]: memory stays bounded.
const PAIRING_WINDOW: i64 = 1_000_000_000;

fn stamp_ns(t: &softcontact_msgs::builtin_interfaces::Time) -> i64 {
    i64::from(t.sec) * 1_000_000_000 + i64::from(t.nanosec)
}

fn seven(v: &[f64]) -> Option<[f64; 7]> {
    <[f64; 7]>::try_from(v).ok().filter(|a| a.iter().all(|x| x.is_finite()))
}

/// The recording's free-space samples, in time order.
pub fn samples(recording: &Recording) -> anyhow::Result<Vec<ArmSample>> {
    anyhow::ensure!(recording.topic(JOINT_STATES).is_some(), "the recording has no {JOINT_STATES}");
    anyhow::ensure!(recording.topic(TORQUE_COMMAND).is_some(), "the recording has no {TORQUE_COMMAND}");
    let mut waiting: BTreeMap<i64, ([f64; 7], [f64; 7])> = BTreeMap::new();
    let mut in_contact = false;
    let mut out = Vec::new();
    for m in recording.messages() {
        let m = m?;
        match m.topic() {
            JOINT_STATES => {
                let js = m.decode::<JointState>()?;
                let t = stamp_ns(&js.header.stamp);
                if let (Some(q), Some(dq)) = (seven(&js.position), seven(&js.velocity))
                    && !in_contact
                {
                    waiting.insert(t, (q, dq));
                }
                waiting.retain(|s, _| *s > t - PAIRING_WINDOW);
            }
            TORQUE_COMMAND => {
                let cmd = m.decode::<JointState>()?;
                // An empty command asks the driver to hold: no torque to learn from.
                let (Some(tau), Some((q, dq))) = (seven(&cmd.effort), waiting.remove(&stamp_ns(&cmd.header.stamp)))
                else {
                    continue;
                };
                out.push(ArmSample { t: cmd.header.stamp.as_secs_f64(), q, dq, tau });
                if out.len() >= MAX_SAMPLES {
                    break;
                }
            }
            WRENCH => {
                let f = m.decode::<WrenchStamped>()?.wrench.force;
                in_contact = (f.x * f.x + f.y * f.y + f.z * f.z).sqrt() > CONTACT;
            }
            _ => {}
        }
    }
    out.sort_by(|a, b| a.t.total_cmp(&b.t));
    out.dedup_by(|a, b| a.t == b.t);
    Ok(out)
}

/// Names the arm's effects in `recording`.
pub fn analyse(recording: &Recording) -> anyhow::Result<ArmReport> {
    let samples = samples(recording)?;
    Ok(name_arm_effects(&lwr4::model(), &samples, ArmOptions::default())?)
}

/// The file the arm's compensation is read from: `DIR/arm_effects.yaml`, the deformation controller's
/// `arm_effects` parameter as an overlay for `--params-file` (launch-scripts/sim.sh and the node take it).
pub const OVERLAY: &str = "arm_effects.yaml";

/// Writes `effects` as the controller's parameter overlay into `dir`; returns its path.
pub fn write_overlay(effects: &ArmEffects, dir: &std::path::Path) -> anyhow::Result<std::path::PathBuf> {
    effects.validate()?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(OVERLAY);
    let body: String = effects.to_yaml().lines().map(|l| format!("      {l}\n")).collect();
    let text = format!(
        "# The arm's own effects named by `softcontact discrepancy --arm`, compensated by the deformation\n\
         # controller: joint friction fed forward, the payload carried in its dynamics.\n\
         deformation_controller:\n  ros__parameters:\n    arm_effects:\n{body}"
    );
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

pub fn print(report: &ArmReport) {
    println!("The arm's own effects ({} free-space samples, against urdf/lwr4.urdf):", report.samples);
    if report.named.is_empty() {
        println!("  named: none — the commanded torques are what the description predicts");
    }
    for e in &report.named {
        match e {
            ArmEffect::JointFriction { viscous, coulomb } => {
                println!("  named: joint_friction");
                println!("    viscous [N m s/rad]: {}", viscous.map(|v| format!("{v:.3}")).join(" "));
                println!("    Coulomb [N m]:       {}", coulomb.map(|v| format!("{v:.3}")).join(" "));
            }
            ArmEffect::PayloadMass { mass, com } => {
                println!(
                    "  named: payload_mass — {mass:.3} kg at [{:.1}, {:.1}, {:.1}] mm in lwr_flange",
                    com[0] * 1e3,
                    com[1] * 1e3,
                    com[2] * 1e3
                );
            }
        }
    }
    println!("  residual per joint [N m RMS], before → after:");
    for j in 0..7 {
        println!("    joint {}: {:.4} → {:.4}", j + 1, report.rms_before[j], report.rms_after[j]);
    }
}
