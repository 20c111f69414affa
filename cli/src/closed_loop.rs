//! `softcontact discrepancy FILE --closed-loop`: does the simulator now behave like the robot that made
//! the recording? The recording's force commands run again through the simulated cell — the product's
//! nodes in lockstep with the simulator, as `softcontact demo` runs them — once on a surface of the
//! baseline model and once on the augmented model the workflow made from the same recording, and the
//! normal force (the sensor's reading), the deformation and the joint angles are compared with the
//! recording's at the same time after the first command: RMS per signal before and after, and a figure.
//!
//! The replayed commands are the recording's first experiment: from its first force command to the
//! first pause between commands three times longer than their usual spacing. The cell starts from the
//! recording's first joint state, finds the surface, holds there and then sends the commands on the
//! recording's schedule; its controller runs the product's policy (the baseline model first, the
//! estimator's newest model at each later command), on both surfaces alike: only the simulated surface
//! differs between the two runs.

use softcontact_msgs::topics;
use std::path::{Path, PathBuf};

use anyhow::Context;
use nalgebra::Vector3;
use plotters::prelude::*;
use serde::Serialize;
use softcontact_bag::Recording;
use softcontact_contact::ContactModel;
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::ForceCommand;
use softcontact_nodes::contact_estimator::{self, ContactEstimatorNode};
use softcontact_nodes::deformation_controller::{ControllerConfig, DeformationController};
use softcontact_sim::{FtSensorConfig, SimConfig, SurfaceConfig};
use softcontact_simcell::cell::Cell;

use crate::discrepancy_cmd::{Analysis, DiscrepancyArgs};

const FORCE_COMMAND: &str = topics::FORCE_COMMAND.name;
const JOINT_STATES: &str = topics::JOINT_STATES.name;
/// The compared samples' spacing \[s\].
const SAMPLE: f64 = 0.01;
/// How long the replayed cell holds in contact before the first command \[s\].
const SETTLE: f64 = 3.0;
/// The most simulated seconds a replay runs (memory and time stay bounded whatever the recording).
const MAX_SECONDS: f64 = 600.0;

/// The recording's signals along one time axis, from its first force command \[s\].
#[derive(Debug, Clone, Default)]
struct Signals {
    t: Vec<f64>,
    /// The sensor's reading along the normal \[N\].
    force: Vec<f64>,
    /// Deformation from the identified surface \[m\].
    deformation: Vec<f64>,
    q: Vec<[f64; 7]>,
}

/// RMS of the replay's difference from the recording, per signal.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Gap {
    pub force_n: f64,
    pub deformation_m: f64,
    /// Over all seven joints \[rad\].
    pub joints_rad: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ClosedLoop {
    pub commands: usize,
    pub seconds: f64,
    /// The replay on the baseline model, and on the augmented one.
    pub rms_before: Gap,
    pub rms_after: Gap,
    pub figure: PathBuf,
}

pub fn run(args: &DiscrepancyArgs, analysis: &Analysis) -> anyhow::Result<ClosedLoop> {
    let recording = Recording::open(&args.recording.file)?;
    let [x, y, z] = args.recording.normal[..] else { anyhow::bail!("--normal takes three numbers") };
    let normal = Vector3::new(x, y, z).normalize();
    let read = read(&recording, &analysis.series.t)?;
    let first_q = read.first_q.with_context(|| format!("the recording has no {JOINT_STATES}"))?;
    let commands = first_experiment(read.commands)?;
    let (t0, t1) = (commands[0].0, commands.last().map_or(0.0, |c| c.0 + c.2) + 0.5);
    anyhow::ensure!(t1 - t0 <= MAX_SECONDS, "the commands span {:.0} s, more than {MAX_SECONDS} s", t1 - t0);
    let recorded = recorded(&read.q_at, analysis, t0, t1)?;
    let report = &analysis.report;
    let augmented_surface = analysis.surface + report.contact_shift * normal;
    println!(
        "closed-loop replay of {} force commands ({:.0} s) through the simulated cell, from the recording's first joint state",
        commands.len(),
        t1 - t0
    );
    let start = Start { q: first_q, deformation: recorded.deformation[0] };
    let before = replay(&commands, t1 - t0, (&analysis.baseline, analysis.surface), analysis, normal, start)
        .context("the replay on the baseline model")?;
    let after = replay(&commands, t1 - t0, (&report.model, augmented_surface), analysis, normal, start)
        .context("the replay on the augmented model")?;
    let (rms_before, rms_after) = (gap(&recorded, &before), gap(&recorded, &after));
    println!("\n{:<14}{:>18}{:>18}", "signal", "baseline model", "augmented model");
    println!("{:<14}{:>16.3} N{:>16.3} N", "force", rms_before.force_n, rms_after.force_n);
    println!(
        "{:<14}{:>15.3} mm{:>15.3} mm",
        "deformation",
        rms_before.deformation_m * 1e3,
        rms_after.deformation_m * 1e3
    );
    println!("{:<14}{:>14.4} rad{:>14.4} rad", "joints", rms_before.joints_rad, rms_after.joints_rad);
    println!("(RMS of the replay's difference from the recording, over the {:.0} s after the first command)", t1 - t0);
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let figure = args.out.join(format!("{}.closed_loop.svg", analysis.name));
    plot(&figure, &recorded, &before, &after).map_err(|e| anyhow::anyhow!("figure: {e}"))?;
    println!("figure: {}", figure.display());
    Ok(ClosedLoop { commands: commands.len(), seconds: t1 - t0, rms_before, rms_after, figure })
}

/// What the replay needs of the recording, read in one pass: every force command (time \[s\], force \[N\],
/// duration \[s\]), the first joint state, and the joint angles in force at each of the workflow's samples
/// (the first joint state stamped at or after it; as many as the series has samples, so memory stays
/// bounded with the series).
struct Read {
    commands: Vec<(f64, f64, f64)>,
    first_q: Option<[f64; 7]>,
    q_at: Vec<[f64; 7]>,
}

fn read(recording: &Recording, series_t: &[f64]) -> anyhow::Result<Read> {
    anyhow::ensure!(recording.topic(FORCE_COMMAND).is_some(), "the recording has no {FORCE_COMMAND} to replay");
    let mut read = Read { commands: Vec::new(), first_q: None, q_at: Vec::new() };
    for m in recording.messages() {
        let m = m?;
        match m.topic() {
            FORCE_COMMAND => {
                let c = m.decode::<ForceCommand>()?;
                anyhow::ensure!(c.force.is_finite() && c.duration.is_finite(), "a force command that is not finite");
                read.commands.push((m.log_time as f64 * 1e-9, c.force, c.duration));
                anyhow::ensure!(read.commands.len() <= 10_000, "more than 10 000 force commands");
            }
            JOINT_STATES => {
                let js = m.decode::<JointState>()?;
                let Ok(q) = <[f64; 7]>::try_from(&js.position[..]) else { continue };
                if read.first_q.is_none() && q.iter().all(|v| v.is_finite()) {
                    read.first_q = Some(q);
                }
                let t = js.header.stamp.as_secs_f64();
                while read.q_at.len() < series_t.len() && series_t[read.q_at.len()] <= t {
                    read.q_at.push(q);
                }
            }
            _ => {}
        }
    }
    Ok(read)
}

/// The first experiment of `all` force commands: up to the first pause three times their usual spacing.
fn first_experiment(mut all: Vec<(f64, f64, f64)>) -> anyhow::Result<Vec<(f64, f64, f64)>> {
    let mut gaps: Vec<f64> = all.windows(2).map(|w| w[1].0 - w[0].0).collect();
    gaps.sort_by(f64::total_cmp);
    let usual = gaps.get(gaps.len() / 2).copied().unwrap_or(f64::INFINITY);
    let end = all.windows(2).position(|w| w[1].0 - w[0].0 > 3.0 * usual).map_or(all.len(), |i| i + 1);
    all.truncate(end);
    anyhow::ensure!(!all.is_empty(), "the recording has no force command");
    Ok(all)
}

/// The recording between t0 and t1 on the replay's time axis: the workflow's series (force and
/// deformation, 10 ms) and the joint angles in force at each of its samples.
fn recorded(q_at: &[[f64; 7]], analysis: &Analysis, t0: f64, t1: f64) -> anyhow::Result<Signals> {
    let s = &analysis.series;
    let mut out = Signals::default();
    for i in (0..s.t.len()).filter(|&i| s.t[i] >= t0 && s.t[i] <= t1) {
        out.t.push(s.t[i] - t0);
        out.force.push(s.f[i]);
        out.deformation.push(s.z[i]);
        if let Some(q) = q_at.get(i) {
            out.q.push(*q);
        }
    }
    anyhow::ensure!(out.t.len() >= 10, "the recording has no force readings after its first command");
    let last = *out.q.last().context("no joint states after the first command")?;
    out.q.resize(out.t.len(), last);
    Ok(out)
}

/// Where the replay starts: the recording's first joint state, and the deformation it held at the first
/// command \[m\].
#[derive(Debug, Clone, Copy)]
struct Start {
    q: [f64; 7],
    deformation: f64,
}

/// The cell on `surface` (a model and a point of its undeformed surface), the controller starting from
/// the baseline model at the identified surface, as the recorded robot did: the commands on their
/// schedule, sampled every 10 ms from the first, the deformation measured from the identified surface.
fn replay(
    commands: &[(f64, f64, f64)],
    seconds: f64,
    (surface_model, surface): (&ContactModel, Vector3<f64>),
    analysis: &Analysis,
    normal: Vector3<f64>,
    start: Start,
) -> anyhow::Result<Signals> {
    let (controller_model, identified) = (&analysis.baseline, analysis.surface);
    let sim = SimConfig {
        initial_q: start.q,
        surface: Some(SurfaceConfig::new(surface, normal, surface_model.clone())),
        sensor: FtSensorConfig::gamma(),
        ..SimConfig::above_surface(surface_model.clone(), 1)
    };
    let most = commands.iter().map(|c| c.1).fold(0.0, f64::max);
    let mut config = ControllerConfig::lwr4((1.25 * most).max(50.0), 0.08);
    config.normal = normal;
    let params = contact_estimator::Params::default();
    let estimator =
        ContactEstimatorNode::new(contact_estimator::EstimatorConfig { normal, ..params.estimator_config() })?;
    let mut cell = Cell::new(sim, DeformationController::new(config, controller_model.clone())?, estimator)?;
    cell.start(5000)?;
    let mut waited = 0;
    while !cell.cycle()?.context("the KRC left command mode")?.controller.in_contact {
        waited += 1;
        anyhow::ensure!(waited < 30_000, "the replayed hand found no surface in 30 s");
    }
    cell.controller.law.adopt_estimate(controller_model.clone(), &identified, None)?;
    // A fresh window from here, as the product's control run starts one (its first model comes while
    // the hand settles).
    cell.estimator =
        ContactEstimatorNode::new(contact_estimator::EstimatorConfig { normal, ..params.estimator_config() })?
            .with_refits(&params, cell.lockstep.sim.time());
    cell.controller.law.command_deformation(start.deformation.clamp(0.0, 0.07), 1.0)?;
    let mut newest = None;
    for _ in 0..(SETTLE / 1e-3) as usize {
        let tick = cell.cycle()?.context("the KRC left command mode")?;
        if let Some(Ok(m)) = cell.estimator.refit_if_due(tick.time) {
            newest = Some(m);
        }
    }
    let t0 = commands[0].0;
    let mut out = Signals::default();
    let mut next = 0;
    let ticks = (seconds / 1e-3).round() as usize;
    for k in 0..=ticks {
        let t = k as f64 * 1e-3;
        while next < commands.len() && commands[next].0 - t0 <= t + 1e-9 {
            let (_, force, duration) = commands[next];
            if next > 0
                && let Some(m) = newest.take()
            {
                // (A model the controller refuses leaves the one in use, as on the robot.)
                let _ = cell.controller.law.adopt_estimate(m.model, &m.contact_position, None);
            }
            cell.controller.law.command_force(force, duration).with_context(|| format!("command {next}"))?;
            next += 1;
        }
        let tick = cell.cycle()?.context("the KRC left command mode")?;
        if let Some(Ok(m)) = cell.estimator.refit_if_due(tick.time) {
            newest = Some(m);
        }
        if k % (SAMPLE / 1e-3).round() as usize == 0 {
            let geometry = cell.controller.geometry();
            out.t.push(t);
            out.force.push(geometry.normal_reading(&tick.force_world));
            out.deformation.push(geometry.deformation(&cell.lockstep.sim.tool_pose().translation.vector, &identified));
            out.q.push(tick.driver.q);
        }
    }
    Ok(out)
}

/// RMS of `replay − recorded` at the recorded samples (the replay's sample nearest in time).
fn gap(recorded: &Signals, replay: &Signals) -> Gap {
    let (mut f, mut z, mut q, mut n) = (0.0, 0.0, 0.0, 0.0);
    for (i, &t) in recorded.t.iter().enumerate() {
        let j = ((t / SAMPLE).round() as usize).min(replay.t.len() - 1);
        f += (replay.force[j] - recorded.force[i]).powi(2);
        z += (replay.deformation[j] - recorded.deformation[i]).powi(2);
        q += (0..7).map(|k| (replay.q[j][k] - recorded.q[i][k]).powi(2)).sum::<f64>() / 7.0;
        n += 1.0;
    }
    Gap { force_n: (f / n).sqrt(), deformation_m: (z / n).sqrt(), joints_rad: (q / n).sqrt() }
}

type Plot = Result<(), Box<dyn std::error::Error>>;
/// A panel: title, unit, and the recording's, the baseline replay's and the augmented replay's curves.
type Curve = Vec<(f64, f64)>;
type Panel<'a> = (&'a str, &'a str, Curve, Curve, Curve);

/// Force, deformation and the joints' distance from the recording over time: the recording (black), the
/// replay on the baseline model (red) and on the augmented model (blue).
fn plot(path: &Path, recorded: &Signals, before: &Signals, after: &Signals) -> Plot {
    let root = SVGBackend::new(path, (1200, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((3, 1));
    let t1 = recorded.t.last().copied().unwrap_or(1.0);
    let range = |v: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        let pad = 0.05 * (hi - lo).max(1e-9);
        (lo - pad)..(hi + pad)
    };
    let joints = |s: &Signals| -> Vec<f64> {
        (0..recorded.t.len())
            .map(|i| {
                let j = ((recorded.t[i] / SAMPLE).round() as usize).min(s.t.len() - 1);
                ((0..7).map(|k| (s.q[j][k] - recorded.q[i][k]).powi(2)).sum::<f64>() / 7.0).sqrt()
            })
            .collect()
    };
    let series: [Panel; 3] = [
        (
            "normal force (sensor reading)",
            "force [N]",
            recorded.t.iter().copied().zip(recorded.force.iter().copied()).collect(),
            before.t.iter().copied().zip(before.force.iter().copied()).collect(),
            after.t.iter().copied().zip(after.force.iter().copied()).collect(),
        ),
        (
            "deformation from the identified surface",
            "deformation [mm]",
            recorded.t.iter().copied().zip(recorded.deformation.iter().map(|z| z * 1e3)).collect(),
            before.t.iter().copied().zip(before.deformation.iter().map(|z| z * 1e3)).collect(),
            after.t.iter().copied().zip(after.deformation.iter().map(|z| z * 1e3)).collect(),
        ),
        (
            "joint angles: RMS distance from the recording",
            "|q − q_recorded| [rad]",
            recorded.t.iter().map(|t| (*t, 0.0)).collect(),
            recorded.t.iter().copied().zip(joints(before)).collect(),
            recorded.t.iter().copied().zip(joints(after)).collect(),
        ),
    ];
    for (panel, (title, unit, rec, bef, aft)) in panels.iter().zip(series) {
        let y = range(&mut rec.iter().chain(&bef).chain(&aft).map(|p| p.1));
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("closed-loop replay: {title}"), ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t1, y)?;
        chart.configure_mesh().x_desc("time after the first command [s]").y_desc(unit).draw()?;
        chart
            .draw_series(LineSeries::new(rec, BLACK))?
            .label("recording")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        chart
            .draw_series(LineSeries::new(bef, RED))?
            .label("replay, baseline model")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        chart
            .draw_series(LineSeries::new(aft, BLUE))?
            .label("replay, augmented model")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        chart.configure_series_labels().border_style(BLACK).background_style(WHITE.mix(0.8)).draw()?;
    }
    root.present()?;
    Ok(())
}
