//! The snake paper's loading paths with the simulated LWR IV as the displacement stage.
//!
//! The cell: the F/T sensor on the flange as in the product's cell (a Nano17-like sensor: 1/1280 N,
//! 5 mN noise), the plate on the sensor — the hand's sole — and the half-ball fixed on the table below
//! it, a surface of the specimen's law (Hertz + the tangential law) 0.3 mm under the sole. The sensor is
//! mounted turned from the plate by the misalignment, about the axis across the loading plane
//! (`FtSensorConfig::mounting`), and the specimen's zero creeps during each experiment
//! (`Surface::creep`): both hidden, only the forces show them.
//!
//! Each experiment runs through the product's own driver and F/T node, in lockstep, one 1 ms FRI cycle
//! at a time: the tool comes down at 1 mm/s until the third reading in a row above 0.03 N (the snake paper's
//! zero, taken where the tool actually is), follows the path from there at 1 mm/s — held by the stiff
//! stage of `softcontact_control::stage` — a sample recorded every 5 µm of the path with δ measured from
//! the tool's actual pose, then lifts and returns. The readings are the sensor's, along its own axes
//! (normal: the plate's normal as mounted nominally; tangential: the loading direction).

use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::rngs::SmallRng;
use rand_distr::{Distribution, Normal};
use softcontact_contact::{ContactModel, LoadingPath};
use softcontact_control::PositionStage;
use softcontact_dynamics::lwr4;
use softcontact_nodes::ft_sensor::{FtConfig, FtSensorNode};
use softcontact_nodes::lwr_driver::{LwrDriver, Params as DriverParams};
use softcontact_sim::{BenchRun, BenchSample, FtSensorConfig, SimConfig, Simulator, ZERO_THRESHOLD};
use softcontact_simcell::cell::Lockstep;
use softcontact_wire::fri::InterfaceState;

/// The stage's bandwidth [rad/s] (ω·dt = 0.15 at the 1 ms cycle).
const BANDWIDTH: f64 = 150.0;
/// Approach and path speed [m/s] (quasi-static: the specimen's law has no rate), and the return's.
const SPEED: f64 = 1e-3;
const RETURN_SPEED: f64 = 5e-3;
/// The sole starts this far above the specimen \[m\].
const HOVER: f64 = 0.3e-3;
/// A sample every this much of the path \[m\] (the ideal bench's step).
const SAMPLE_STEP: f64 = 5e-6;

/// The experiments as the arm ran them, and how well the stage tracked.
pub struct ArmRuns {
    pub runs: Vec<BenchRun>,
    /// RMS and largest distance of the tool from its reference along the paths \[m\].
    pub tracking_rms: f64,
    pub tracking_max: f64,
    /// Simulated seconds.
    pub simulated: f64,
}

/// The hidden part of the cell (the truth; never read by the fits).
pub struct HiddenErrors {
    /// Standard deviation of the creep of the zero over one experiment \[m\].
    pub creep_sd: f64,
    /// The sensor's axes turned from the plate's in the loading plane \[rad\].
    pub misalignment: f64,
    /// White noise of each force axis \[N\].
    pub noise: f64,
    pub seed: u64,
}

struct Cell {
    lockstep: Lockstep,
    stage: PositionStage,
    /// The sensor's orientation in the tool frame (the URDF's), and in the world at the last cycle.
    tool_to_sensor: UnitQuaternion<f64>,
    sensor_orientation: UnitQuaternion<f64>,
    /// The contact normal n and the loading direction, in the world and in the sensor's nominal axes.
    normal: Vector3<f64>,
    along: Vector3<f64>,
    normal_sensor: Vector3<f64>,
    along_sensor: Vector3<f64>,
}

/// What one cycle saw: the tool's actual position and the sensor's normal and tangential readings.
struct Seen {
    commanding: bool,
    position: Vector3<f64>,
    normal: f64,
    tangential: f64,
}

impl Cell {
    fn new(truth: &ContactModel, hidden: &HiddenErrors) -> anyhow::Result<Self> {
        let mut config = SimConfig::above_surface(truth.clone(), hidden.seed);
        let surface = config.surface.as_mut().expect("above_surface has a surface");
        let normal = surface.normal;
        surface.point += (HOVER - 0.04) * normal;
        let model = lwr4::model();
        let mut data = model.data();
        model.forward_kinematics(&mut data, &config.initial_q);
        let sensor = model.frame_id(lwr4::FT_SENSOR_FRAME)?;
        let sensor_rotation = model.frame_pose(&data, sensor).rotation;
        let along = Vector3::x();
        let across = normal.cross(&along);
        let mounting = UnitQuaternion::from_scaled_axis(sensor_rotation.inverse() * across * -hidden.misalignment);
        config.sensor = FtSensorConfig { mounting, ..FtSensorConfig::nano17() };
        config.sensor.noise[..3].fill(hidden.noise);
        let ft = FtSensorNode::new(FtConfig::lwr4(config.sensor.calibration)).map_err(anyhow::Error::msg)?;
        let tool = model.frame_id(lwr4::TOOL_FRAME)?;
        let stage = PositionStage::new(lwr4::model(), tool, &config.initial_q, BANDWIDTH);
        Ok(Self {
            lockstep: Lockstep { sim: Simulator::new(config)?, driver: LwrDriver::new(DriverParams::default()), ft },
            stage,
            normal_sensor: sensor_rotation.inverse() * normal,
            along_sensor: sensor_rotation.inverse() * along,
            normal,
            along,
            tool_to_sensor: softcontact_control::contact_task::lwr4_tool_to_sensor().rotation,
            sensor_orientation: sensor_rotation,
        })
    }

    /// One FRI cycle, read → update → write: the tool driven to `reference` moving at `velocity`.
    fn cycle(&mut self, reference: &Vector3<f64>, velocity: &Vector3<f64>) -> anyhow::Result<Seen> {
        let Self { lockstep, stage, tool_to_sensor, sensor_orientation, normal_sensor, along_sensor, .. } = self;
        let dt = lockstep.sim.krc_cycle();
        let (seen, _) = lockstep.cycle(|mut c| -> anyhow::Result<Seen> {
            let (q, dq) = (c.measured.q, c.measured.dq);
            // The cycle's kinematics, the stage's (its update reuses them).
            let tool = stage.tool_motion(&q, &dq);
            let orientation = tool.pose.rotation * *tool_to_sensor;
            *sensor_orientation = orientation;
            let ft = c.read_ft(&tool.pose, &orientation)?;
            anyhow::ensure!(!(ft.invalid && ft.fresh), "the F/T sensor's reading is invalid (saturated?)");
            let reading = match ft.compensated.filter(|_| c.ft.tared()) {
                Some(f) => Vector3::new(f[0], f[1], f[2]),
                None => Vector3::zeros(),
            };
            let commanding = c.measured.state == InterfaceState::Command;
            if commanding {
                let tau = stage.update(&q, &dq, reference, velocity, &(orientation * reading), dt)?;
                c.driver.set_command(&tau)?;
            }
            Ok(Seen {
                commanding,
                position: tool.pose.translation.vector,
                // The force on the hand, along the sensor's axes: the specimen pushes back.
                normal: -reading.dot(normal_sensor),
                tangential: -reading.dot(along_sensor),
            })
        })?;
        let driver = &self.lockstep.driver;
        anyhow::ensure!(
            driver.fault().is_none(),
            "the driver holds for a fault: {}",
            driver.fault().map(|f| f.to_string()).unwrap_or_default()
        );
        Ok(seen)
    }

    /// Moves the reference in a straight line from `from` to `to` at `speed`; the positions seen.
    fn travel(&mut self, from: Vector3<f64>, to: Vector3<f64>, speed: f64) -> anyhow::Result<Seen> {
        let d = to - from;
        let cycles = ((d.norm() / (speed * self.lockstep.sim.krc_cycle())).ceil() as usize).max(1);
        let velocity = d / (cycles as f64 * self.lockstep.sim.krc_cycle());
        let mut last = None;
        for k in 1..=cycles {
            last = Some(self.cycle(&(from + d * (k as f64 / cycles as f64)), &velocity)?);
        }
        Ok(last.expect("at least one cycle"))
    }
}

/// Runs `paths` (displacements from each experiment's found zero) with the arm as the stage.
pub fn run(truth: &ContactModel, paths: &[LoadingPath], hidden: &HiddenErrors) -> anyhow::Result<ArmRuns> {
    let mut cell = Cell::new(truth, hidden)?;
    let mut rng = SmallRng::seed_from_u64(hidden.seed ^ 0x05ee_d000);
    let creep = Normal::new(0.0, hidden.creep_sd).map_err(|e| anyhow::anyhow!("creep: {e}"))?;
    let home = cell.stage.tool_position(cell.lockstep.sim.q());
    // Until the KRC commands, then still for 0.3 s, then the F/T node tares with the hand free.
    let mut commanding = 0;
    for _ in 0..5000 {
        commanding = if cell.cycle(&home, &Vector3::zeros())?.commanding { commanding + 1 } else { 0 };
        if commanding > 300 {
            break;
        }
    }
    anyhow::ensure!(commanding > 300, "the KRC did not enter command mode");
    cell.lockstep.ft.checked_tare(Some(&cell.sensor_orientation)).map_err(|e| anyhow::anyhow!("tare: {e}"))?;
    let (n, t) = (cell.normal, cell.along);
    let (mut runs, mut sum, mut count, mut worst) = (Vec::with_capacity(paths.len()), 0.0, 0usize, 0.0f64);
    for path in paths {
        let creep = creep.sample(&mut rng);
        // Down at 1 mm/s until the third reading above the threshold: the zero, where the tool is.
        let (mut reference, mut above, mut zero) = (home, 0, None);
        let step = n * SPEED * cell.lockstep.sim.krc_cycle();
        for _ in 0..(3.0 * HOVER / (SPEED * cell.lockstep.sim.krc_cycle())) as usize {
            reference += step;
            let seen = cell.cycle(&reference, &(n * SPEED))?;
            above = if seen.normal > ZERO_THRESHOLD { above + 1 } else { 0 };
            if above == 3 {
                zero = Some(seen.position);
                break;
            }
        }
        let zero = zero.ok_or_else(|| anyhow::anyhow!("the arm found no specimen within {} mm", 3e3 * HOVER))?;
        let surface = cell.lockstep.sim.surface.as_ref().expect("a surface").config().point;
        let zero_error = (zero - surface).dot(&n);
        // Along the path from the zero, the zero creeping with the path's progress.
        let length = path.length();
        let (mut samples, mut from, mut travelled, mut next_sample) = (Vec::new(), [0.0, 0.0], 0.0, SAMPLE_STEP);
        let start = reference;
        let mut crept = 0.0;
        for w in &path.waypoints {
            let segment = (w[0] - from[0]).hypot(w[1] - from[1]);
            let cycles = ((segment / (SPEED * cell.lockstep.sim.krc_cycle())).ceil() as usize).max(1);
            let direction = (n * (w[0] - from[0]) + t * (w[1] - from[1])) / segment.max(1e-12);
            for k in 1..=cycles {
                let u = k as f64 / cycles as f64;
                let (dn, dt) = (from[0] + u * (w[0] - from[0]), from[1] + u * (w[1] - from[1]));
                let progress = if length > 0.0 { (travelled + u * segment) / length } else { 1.0 };
                let surface = cell.lockstep.sim.surface.as_mut().expect("a surface");
                surface.creep(creep * progress - crept);
                crept = creep * progress;
                let target = start + n * dn + t * dt;
                let seen = cell.cycle(&target, &(direction * SPEED))?;
                let e = (seen.position - target).norm();
                (sum, count, worst) = (sum + e * e, count + 1, worst.max(e));
                if travelled + u * segment >= next_sample - 1e-12
                    || (k == cycles && w == path.waypoints.last().unwrap())
                {
                    next_sample += SAMPLE_STEP;
                    let d = seen.position - zero;
                    samples.push(BenchSample {
                        normal_displacement: d.dot(&n),
                        tangential_displacement: d.dot(&t),
                        normal_force: seen.normal,
                        tangential_force: seen.tangential,
                    });
                }
                reference = target;
            }
            travelled += segment;
            from = *w;
        }
        // Up off the specimen, back over home, and still.
        let lifted = home + t * (reference - home).dot(&t);
        cell.travel(reference, lifted, RETURN_SPEED)?;
        cell.travel(lifted, home, RETURN_SPEED)?;
        for _ in 0..20 {
            cell.cycle(&home, &Vector3::zeros())?;
        }
        runs.push(BenchRun { samples, creep, zero_error });
    }
    Ok(ArmRuns {
        runs,
        tracking_rms: (sum / count.max(1) as f64).sqrt(),
        tracking_max: worst,
        simulated: cell.lockstep.sim.time(),
    })
}
