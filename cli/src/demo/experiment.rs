//! The force-control paper's two experiments on one simulated surface, in lockstep with the simulator: the same node
//! structs as the graph, no DDS. Identification: 10 runs of a ramp into contact, 1 Hz sinusoidal
//! pushes and a retreat; every kind fitted to all of it with 5-fold cross-validation. Control: 30 force
//! commands reached by 2 s quintics, cycle 1 through the identified model, then the estimator's model
//! of the last 1200 samples (12 s at 10 ms) adopted at each command.

use anyhow::Context;
use nalgebra::Vector3;
use softcontact_contact::{ContactModel, Fit, Kind};
use softcontact_nodes::contact_estimator::{self, ContactEstimatorNode, ModelOut};
use softcontact_nodes::deformation_controller::{ControllerConfig, DeformationController};
use softcontact_sim::{FtSensorConfig, SimConfig};
use softcontact_simcell::cell::{Cell, Tick};

/// The ratios of the maximum identified force that the force-control paper commands: 4 cycles of the first six,
/// then one of the second six.
pub const RATIOS: [[f64; 6]; 2] = [[0.8, 0.4, 0.7, 0.3, 0.5, 0.6], [0.75, 0.35, 0.65, 0.25, 0.45, 0.55]];
pub const CYCLES: usize = 5;

/// One surface and how the experiments treat it.
#[derive(Debug, Clone)]
pub struct SurfaceSpec {
    pub name: &'static str,
    /// What the simulator's surface is made of (the truth, effects included).
    pub truth: ContactModel,
    /// Identification pushes between these deformations \[m\] (the force-control paper: up to 5 cm sponge, 7 cm dice).
    pub push: (f64, f64),
    /// Identification pushes of the `--graph` run, by force commands: high and low \[N\].
    pub push_forces: (f64, f64),
    /// The controller's limits on this surface: force \[N\], deformation \[m\].
    pub max_force: f64,
    pub max_deformation: f64,
    /// The simulated F/T sensor (the demo's drifts as a Gamma warming up; tared before each experiment).
    pub sensor: FtSensorConfig,
    /// Surface effects outside the library ([`softcontact_sim::foreign`]), added to `truth`'s force: the
    /// corpus's foreign cases.
    pub foreign: Vec<softcontact_sim::foreign::ForeignEffect>,
}

/// How much of the experiments to run (the full set is the force-control paper's).
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    pub identification_runs: usize,
    pub push_periods: u32,
    /// Control commands (30: five cycles of six).
    pub commands: usize,
    pub move_duration: f64,
    /// Lateral sway during every push run and force command (a tangential load) and tilts of the hand in
    /// free space after every push run (the sensor's orientation against gravity): the excitation
    /// crosstalk and an unknown tool weight need, spread through the recording so that every fold of the
    /// workflow's cross-validation sees some.
    pub across: Across,
    /// The hand starts this deep \[m\] in the surface instead of 4 cm above it, so that the start-up tare
    /// takes the contact force for the sensor's zero, and control starts without a second tare: the
    /// whole recording then reads a constant offset (a sensor bias, as after a tare taken touching).
    pub start_pressed: Option<f64>,
    /// After identification, run the discrepancy workflow on its runs and the control experiment a
    /// second time through the augmented model.
    pub augmented: bool,
}

impl Plan {
    pub const SEED_001: Plan = Plan {
        identification_runs: 10,
        push_periods: 5,
        commands: 30,
        move_duration: 2.0,
        across: Across::No,
        start_pressed: None,
        augmented: true,
    };
}

/// Which ways [`Plan::across`] moves the hand across the surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Across {
    No,
    /// Sway along x, each way in turn, and tilts about y.
    AlongX,
    /// Sway along x, y, −x, −y in turn, and tilts about y and x in turn: a tangential load in every
    /// direction of the surface's plane, for a sensor turned about any axis.
    AlongXAndY,
}

impl Across {
    /// The lateral offset of the `i`-th push run or force command \[m\].
    fn sway(self, i: usize) -> Vector3<f64> {
        match self {
            Across::No => Vector3::zeros(),
            Across::AlongX => Vector3::new(SWAY * if i.is_multiple_of(2) { 1.0 } else { -1.0 }, 0.0, 0.0),
            Across::AlongXAndY => {
                let way = if i % 4 < 2 { SWAY } else { -SWAY };
                if i.is_multiple_of(2) { Vector3::new(way, 0.0, 0.0) } else { Vector3::new(0.0, way, 0.0) }
            }
        }
    }

    /// The tilt of the hand in free space after the `i`-th push run \[rad\].
    fn tilt(self, i: usize) -> Vector3<f64> {
        let way = if i.is_multiple_of(2) { TILT } else { -TILT };
        match self {
            Across::No => Vector3::zeros(),
            Across::AlongX => Vector3::new(0.0, way, 0.0),
            Across::AlongXAndY if i % 4 < 2 => Vector3::new(0.0, way, 0.0),
            Across::AlongXAndY => Vector3::new(way, 0.0, 0.0),
        }
    }
}

/// Which model a command went through (docs/contracts.md: a command's `model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelUse {
    /// The model in use: the identified one in cycle 1, the online estimate after.
    Identified,
    /// Cycle 1 again, with the model the discrepancy workflow augmented.
    Augmented,
}

/// One control command and what was reached, graded on the simulator's true contact force.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct CommandResult {
    pub cycle: usize,
    pub ratio: f64,
    pub command: f64,
    /// The true normal contact force at the end of the move (the simulator's) \[N\].
    pub reached: f64,
    /// The same as the F/T sensor read it (tared, gravity compensated) \[N\].
    pub reached_measured: f64,
    /// |reached − command| \[N\].
    pub error: f64,
    /// |reached_measured − command| \[N\].
    pub error_measured: f64,
    pub model: ModelUse,
    /// The stiffness of the model the command went through (JSON null: not known to the client).
    #[serde(deserialize_with = "nan_if_null")]
    pub model_stiffness: f64,
}

fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::NAN))
}

impl CommandResult {
    /// Command `i` (from 0) of the force-control paper's sequence: its cycle (from 1), ratio and force \[N\].
    pub fn planned(i: usize, max_force: f64) -> (usize, f64, f64) {
        let cycle = i / 6 + 1;
        let ratio = RATIOS[usize::from(cycle == CYCLES)][i % 6];
        (cycle, ratio, ratio * max_force)
    }

    /// Command `i`'s result, with the error as the force-control paper measures it: |actual − command|, on the true
    /// force `reached` and on the sensor's `reached_measured`.
    pub fn new(i: usize, max_force: f64, reached: f64, reached_measured: f64, model_stiffness: f64) -> Self {
        let (cycle, ratio, command) = Self::planned(i, max_force);
        Self {
            cycle,
            ratio,
            command,
            reached,
            reached_measured,
            error: (reached - command).abs(),
            error_measured: (reached_measured - command).abs(),
            model: ModelUse::Identified,
            model_stiffness,
        }
    }
}

/// Samples for the figures, every 10 ms.
#[derive(Debug, Clone, Default)]
pub struct Series {
    pub time: Vec<f64>,
    /// Identification: reference and actual deformation (one run).
    pub z_cmd: Vec<f64>,
    pub z: Vec<f64>,
    /// Control: actual, predicted and commanded normal force.
    pub force: Vec<f64>,
    pub predicted: Vec<f64>,
    pub command: Vec<f64>,
}

/// One control experiment: the force over it (every 10 ms) and the times \[s\] its commands were sent.
#[derive(Debug, Clone, Default)]
pub struct Control {
    pub series: Series,
    pub command_times: Vec<f64>,
}

/// What the discrepancy workflow found in the identification runs.
#[derive(Debug, Clone)]
pub struct Found {
    pub report: softcontact_discrepancy::Report,
    /// The augmented model and where it places the surface in the world.
    pub model: ContactModel,
    pub contact_position: Vector3<f64>,
}

/// Everything one surface's experiments produced.
pub struct SurfaceRun {
    pub spec: SurfaceSpec,
    pub identified: ModelOut,
    pub identification_samples: usize,
    pub max_force: f64,
    /// Every command of both control experiments (`model` tells them apart).
    pub commands: Vec<CommandResult>,
    pub identification: Series,
    /// The control experiment through the identified model.
    pub control: Control,
    /// What the discrepancy workflow named in the identification runs, and the control experiment
    /// through the augmented model.
    pub augmented: Option<(Found, Control)>,
    /// Simulated seconds of the whole run.
    pub simulated: f64,
}

impl SurfaceRun {
    pub fn selected(&self) -> Kind {
        self.identified.estimate.selected
    }

    pub fn fits(&self) -> &[Fit] {
        &self.identified.estimate.fits
    }
}

/// Receives every tick and every model, to record them (or not).
pub trait Observer {
    fn tick(&mut self, tick: &Tick) -> anyhow::Result<()>;
    fn model(&mut self, time: f64, model: &ModelOut) -> anyhow::Result<()>;
    fn force_command(&mut self, time: f64, force: f64, duration: f64) -> anyhow::Result<()>;
}

pub struct NoObserver;

impl Observer for NoObserver {
    fn tick(&mut self, _: &Tick) -> anyhow::Result<()> {
        Ok(())
    }
    fn model(&mut self, _: f64, _: &ModelOut) -> anyhow::Result<()> {
        Ok(())
    }
    fn force_command(&mut self, _: f64, _: f64, _: f64) -> anyhow::Result<()> {
        Ok(())
    }
}

const CYCLE: f64 = 1e-3;
const RETREAT: f64 = -0.01;
/// [`Plan::across`]: the lateral sway \[m\] (each way) and the tilt of the hand \[rad\].
const SWAY: f64 = 0.008;
const TILT: f64 = 0.35;

/// The cell driven tick by tick, the estimator refitting on the node's own schedule (when it has one).
struct Runner<'a, O: Observer> {
    cell: Cell,
    observer: &'a mut O,
    newest: Option<ModelOut>,
    last: Tick,
}

impl<O: Observer> Runner<'_, O> {
    fn tick(&mut self) -> anyhow::Result<&Tick> {
        let tick = self.cell.cycle()?.context("the KRC left command mode")?;
        anyhow::ensure!(!tick.controller.contact_lost, "contact lost at t = {:.3} s", tick.time);
        self.observer.tick(&tick)?;
        if let Some(model) = self.cell.estimator.refit_if_due(tick.time) {
            let model = model?;
            self.observer.model(tick.time, &model)?;
            self.newest = Some(model);
        }
        self.last = tick;
        Ok(&self.last)
    }

    /// Approach: the hand descends at 1 cm/s until the controller's onset fires.
    fn approach(&mut self, name: &str) -> anyhow::Result<()> {
        let mut waited = 0.0;
        while !self.tick()?.controller.in_contact {
            waited += CYCLE;
            anyhow::ensure!(waited < 20.0, "{name}: no contact after 20 s");
        }
        Ok(())
    }

    fn run(&mut self, seconds: f64, mut each: impl FnMut(&Tick)) -> anyhow::Result<()> {
        for _ in 0..(seconds / CYCLE).round() as usize {
            each(self.tick()?);
        }
        Ok(())
    }
}

/// The cell on `spec`'s surface (as `sim` places it) with its sensor, started (the KRC commands and the
/// F/T node has tared), the estimator on the node's schedule.
fn start<'a, O: Observer>(
    spec: &SurfaceSpec,
    mut sim: SimConfig,
    controller_model: ContactModel,
    estimator: contact_estimator::EstimatorConfig,
    observer: &'a mut O,
) -> anyhow::Result<Runner<'a, O>> {
    sim.sensor = spec.sensor.clone();
    if let Some(surface) = sim.surface.as_mut() {
        surface.foreign = spec.foreign.clone();
    }
    let controller =
        DeformationController::new(ControllerConfig::lwr4(spec.max_force, spec.max_deformation), controller_model)?;
    let mut cell = Cell::new(sim, controller, ContactEstimatorNode::new(estimator)?)?;
    let last = cell.start(5000)?;
    Ok(Runner { cell, observer, newest: None, last })
}

/// One long hold, as when a surface identified earlier is pressed again: the sensor tared out of contact
/// at start-up, the hand lowered onto the surface, the controller given `model` (the surface where the
/// simulator has it), one force command of `force` \[N\] over 2 s and a hold of `hold` seconds; the
/// recording ends in contact. Over such a hold a drifting sensor and a creeping surface read alike.
pub fn run_hold(
    spec: &SurfaceSpec,
    model: &ContactModel,
    force: f64,
    hold: f64,
    seed: u64,
    observer: &mut impl Observer,
) -> anyhow::Result<f64> {
    let sim = SimConfig::above_surface(spec.truth.clone(), seed);
    let surface = sim.surface.as_ref().context("a surface")?.point;
    let estimator = contact_estimator::Params::default().estimator_config();
    let mut r = start(spec, sim, model.clone(), estimator, observer)?;
    r.approach(spec.name)?;
    r.cell.controller.law.adopt_estimate(model.clone(), &surface, None)?;
    r.cell.controller.law.command_force(force, 2.0)?;
    r.observer.force_command(r.last.time, force, 2.0)?;
    r.run(2.0 + hold, |_| {})?;
    Ok(r.last.time)
}

/// Runs both experiments on one surface.
pub fn run_surface(
    spec: &SurfaceSpec,
    plan: Plan,
    seed: u64,
    observer: &mut impl Observer,
) -> anyhow::Result<SurfaceRun> {
    let mut sim = SimConfig::above_surface(spec.truth.clone(), seed);
    if let (Some(depth), Some(surface)) = (plan.start_pressed, sim.surface.as_mut()) {
        surface.point -= (0.04 + depth) * surface.normal;
    }
    let params = contact_estimator::Params::default();
    // Identification keeps every sample of every run (the force-control paper fits all of them at once).
    let identification = contact_estimator::EstimatorConfig { window: 100_000, ..params.estimator_config() };
    // The controller knows nothing of the surface yet: it only moves the hand during identification.
    let guess = ContactModel::new(Kind::KelvinVoigt, 5000.0, 0.0)?;
    let mut r = start(spec, sim, guess, identification, observer)?;
    let tared_at = r.last.time;
    r.approach(spec.name)?;

    // Identification: ramp into the lowest push point, 1 Hz pushes, retreat, rest; 10 times.
    let mut id_series = Series::default();
    // (t, z from the onset, ż, the reading along n, unclamped) every 10 ms of every run, for the
    // discrepancy workflow (in free space the reading is the sensor's noise, bias and drift).
    let mut recorded = Vec::new();
    let geometry = *r.cell.controller.geometry();
    let mut max_force: f64 = 0.0;
    let (low, high) = spec.push;
    for run in 0..plan.identification_runs {
        let mut k = 0usize;
        let mut watch = |t: &Tick| {
            max_force = max_force.max(t.controller.f);
            if k.is_multiple_of(10) {
                let c = &t.controller;
                recorded.push((t.time, c.z, c.zdot, geometry.normal_reading(&t.force_world)));
            }
            if run == 0 && k.is_multiple_of(10) {
                id_series.time.push(t.time);
                id_series.z_cmd.push(t.controller.z_cmd);
                id_series.z.push(t.controller.z);
            }
            k += 1;
        };
        r.cell.controller.law.command_pushes(low, high, 1.0, plan.push_periods)?;
        let sway = plan.across.sway(run);
        if plan.across != Across::No {
            // Across the surface while pushing: the tangential load, in every run.
            r.cell.controller.law.command_across(sway, Vector3::zeros(), 2.0)?;
        }
        r.run(1.0 + f64::from(plan.push_periods), &mut watch)?;
        r.cell.controller.law.command_deformation(RETREAT, 1.0)?;
        r.run(1.5, &mut watch)?;
        if plan.across != Across::No {
            // Tilt the hand in free space and back: the sensor's orientation against gravity.
            for to in [plan.across.tilt(run), Vector3::zeros()] {
                r.cell.controller.law.command_across(sway, to, 3.0)?;
                r.run(3.5, &mut watch)?;
            }
        }
    }
    let identification_samples = r.cell.estimator.samples();
    let identified = r.cell.estimator.refit().context("identification fit")?;
    r.observer.model(r.last.time, &identified)?;
    let found = if plan.augmented {
        let normal = r.cell.controller.law.config().normal;
        Some(
            discrepancy(&recorded, tared_at, &identified, &normal)
                .with_context(|| format!("{}: discrepancy", spec.name))?,
        )
    } else {
        None
    };

    // Control: a fresh estimator (its window: the last 1200 samples of the control run), the sensor
    // tared out of contact, and the identified model for cycle 1.
    let (control, mut commands) =
        run_control(&mut r, plan, max_force, (&identified.model, &identified.contact_position), ModelUse::Identified)?;
    let augmented = match found {
        Some(found) => {
            // The same experiment again, cycle 1 through the augmented model.
            let (run, more) =
                run_control(&mut r, plan, max_force, (&found.model, &found.contact_position), ModelUse::Augmented)?;
            commands.extend(more);
            Some((found, run))
        }
        None => None,
    };
    Ok(SurfaceRun {
        spec: spec.clone(),
        identified,
        identification_samples,
        max_force,
        commands,
        identification: id_series,
        control,
        augmented,
        simulated: r.last.time,
    })
}

/// The discrepancy workflow on the identification runs (10 ms samples, deformation from the identified
/// surface): what the identified model misses, named, and the model augmented with it.
fn discrepancy(
    recorded: &[(f64, f64, f64, f64)],
    tared_at: f64,
    identified: &ModelOut,
    normal: &Vector3<f64>,
) -> anyhow::Result<Found> {
    let column = |i: usize| recorded.iter().map(|s| [s.0, s.1, s.2, s.3][i]).collect::<Vec<f64>>();
    let z = recorded.iter().map(|s| s.1 - identified.offset).collect();
    let series =
        softcontact_discrepancy::Series::new(column(0), z, column(2), column(3))?.with_tares(vec![tared_at])?;
    let report = softcontact_discrepancy::analyse(&series, &identified.model, &Default::default())?;

    Ok(Found {
        model: report.model.clone(),
        contact_position: identified.contact_position + report.contact_shift * normal,
        report,
    })
}

/// One control experiment of `plan.commands` force commands on the running cell: a fresh estimator (its
/// window: the last 1200 samples of this experiment), the sensor tared out of contact, `model` (placing
/// the surface at the given point) for cycle 1 and the estimator's newest model at each command after.
fn run_control<O: Observer>(
    r: &mut Runner<'_, O>,
    plan: Plan,
    max_force: f64,
    (model, surface): (&ContactModel, &Vector3<f64>),
    use_: ModelUse,
) -> anyhow::Result<(Control, Vec<CommandResult>)> {
    let params = contact_estimator::Params::default();
    if plan.start_pressed.is_none() {
        r.cell.controller.law.command_deformation(RETREAT, 1.0)?;
        r.run(1.5, |_| {})?;
        r.cell.tare()?;
    }
    let mut estimator = ContactEstimatorNode::new(params.estimator_config())?.with_refits(&params, r.last.time);
    if use_ == ModelUse::Augmented {
        // The estimator carries the named effects in its window fits, the surface where the workflow
        // placed it.
        estimator = estimator.with_effects(model.clone(), Some(*surface))?;
    }
    r.cell.estimator = estimator;
    r.newest = None;
    r.cell.controller.law.adopt_estimate(model.clone(), surface, None)?;
    r.cell.controller.law.command_deformation(0.005, 2.0)?;
    r.run(3.0, |_| {})?;

    let mut run = Control::default();
    let mut commands = Vec::with_capacity(plan.commands);
    let mut k = 0usize;
    for i in 0..plan.commands {
        let (cycle, _, command) = CommandResult::planned(i, max_force);
        if cycle > 1
            && let Some(m) = r.newest.take()
        {
            // The force-control paper: from cycle 2 on, the newest model of the last 12 s at each command.
            r.cell.controller.law.adopt_estimate(m.model, &m.contact_position, None)?;
        }
        let stiffness = r.cell.controller.law.contact_model().stiffness;
        r.cell.controller.law.command_force(command, plan.move_duration)?;
        if plan.across != Across::No {
            r.cell.controller.law.command_across(plan.across.sway(i), Vector3::zeros(), plan.move_duration)?;
        }
        r.observer.force_command(r.last.time, command, plan.move_duration)?;
        run.command_times.push(r.last.time);
        let cycles = (plan.move_duration / CYCLE).round() as usize;
        let (mut end, mut end_true) = (Vec::with_capacity(10), Vec::with_capacity(10));
        for j in 0..cycles {
            let t = r.tick()?;
            if k.is_multiple_of(10) {
                let s = &mut run.series;
                s.time.push(t.time);
                s.force.push(t.controller.f);
                s.predicted.push(t.controller.f_predicted);
                s.command.push(t.controller.f_cmd);
            }
            k += 1;
            if j + 10 >= cycles {
                end.push(t.controller.f);
                end_true.push(r.cell.lockstep.sim.contact().normal_force);
            }
        }
        // The force at the end of the move (the last 10 ms, one sample of the force-control paper's 100 Hz).
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let result = CommandResult::new(i, max_force, mean(&end_true), mean(&end), stiffness);
        commands.push(CommandResult { model: use_, ..result });
    }
    Ok((run, commands))
}
