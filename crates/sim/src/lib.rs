//! The simulated KUKA LWR IV, its KRC, a soft surface and an ATI Gamma F/T sensor: pure, steppable and
//! deterministic from a seed. It produces and consumes the real wire structs (FRI measurement and
//! command, RDT records), so the very driver code that runs on the robot closes the loop against it.
//!
//! Integration: semi-implicit (symplectic) Euler at a fixed step (default 1 ms, one per FRI cycle, as
//! the KRC holds each command for a cycle), one forward-dynamics evaluation per step. It is stable
//! while ω·dt < 2 for every mode and keeps energy bounded instead of drifting; the stiffest modes here
//! are the hand on the surface (sponge: ∂f/∂z ≈ 8 kN/m on ≈ 3 kg of effective mass, ω ≈ 55 rad/s;
//! dice ≈ 2 kN/m, ω ≈ 25 rad/s) and the wrist under a joint spring (≈ 100–300 rad/s), all below
//! ω·dt = 0.3 at 1 ms: a margin of more than 6. `SimConfig::step` can be made finer.

pub mod excitation;
pub mod foreign;
mod krc;
mod sensor;
mod specimen;
mod surface;

pub use krc::{
    ALL_DRIVES, Drive, KRL_INIT, Krc, KrcConfig, KrcEvent, KrlProgram, QualityPolicy, STRATEGY_CARTESIAN_IMPEDANCE,
    STRATEGY_JOINT_IMPEDANCE, STRATEGY_POSITION, control_mode,
};
pub use sensor::{FtSensor, FtSensorConfig};
pub use specimen::{BenchRun, BenchSample, SpecimenBench, SpecimenConfig, ZERO_THRESHOLD};
pub use surface::{Contact, Surface, SurfaceConfig};

use nalgebra::{Isometry3, Vector3};
use rand::SeedableRng;
use rand::rngs::SmallRng;
use softcontact_contact::ContactModel;
use softcontact_dynamics::{Data, ExternalWrench, FrameId, Model, lwr4};
use softcontact_wire::{fri, rdt};

/// Why the simulator refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("invalid simulator configuration: {0}")]
    Config(String),
    #[error(transparent)]
    Dynamics(#[from] softcontact_dynamics::Error),
    #[error(transparent)]
    Contact(#[from] softcontact_contact::ContactError),
}

/// The arm's own effects the simulator can hide (crates/dynamics arm_effects.rs): joint friction, and
/// a load on the flange the robot's description does not know (an adapter plate, cables) that weighs on
/// the arm while the F/T sensor beyond it does not feel it. Only the simulated physics carries them.
pub use softcontact_dynamics::{JointFriction, Payload};

/// Everything that defines a simulated run.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// Integration step \[s\]; the FRI cycle is a whole number of steps.
    pub step: f64,
    /// FRI cycle \[s\].
    pub cycle: f64,
    pub initial_q: [f64; 7],
    pub friction: Option<JointFriction>,
    /// A hidden payload on the flange (the KRC, like the product, knows only the URDF's arm).
    pub payload: Option<Payload>,
    pub krc: KrcConfig,
    pub surface: Option<SurfaceConfig>,
    pub sensor: FtSensorConfig,
    pub seed: u64,
}

impl SimConfig {
    /// The hand at [`DEFAULT_Q`], facing down 4 cm above a horizontal soft surface made of `model`
    /// (the force-control paper's start).
    pub fn above_surface(model: ContactModel, seed: u64) -> Self {
        let normal = Vector3::new(0.0, 0.0, -1.0);
        let arm = lwr4::model();
        let mut data = arm.data();
        arm.forward_kinematics(&mut data, &DEFAULT_Q);
        let sole = arm.frame_pose(&data, arm.frame_id(lwr4::TOOL_FRAME).expect("lwr_tool")).translation.vector;
        Self {
            step: 1e-3,
            cycle: 1e-3,
            initial_q: DEFAULT_Q,
            friction: None,
            payload: None,
            krc: KrcConfig::default(),
            surface: Some(SurfaceConfig::new(sole + 0.04 * normal, normal, model)),
            sensor: FtSensorConfig::gamma(),
            seed,
        }
    }
}

/// The hand beyond the sensing frame as the sensor feels it: the URDF's, plus the tool mass a surface
/// model's [`softcontact_contact::Effect::ToolGravity`] says the compensation does not know, at the same
/// centre of mass. (The arm's dynamics keep the URDF's hand: a payload error is a separate effect.)
fn sensed_load(surface: Option<&SurfaceConfig>) -> softcontact_dynamics::BodyInertia {
    let mut load = lwr4::tool_load();
    let extra: f64 = surface
        .into_iter()
        .flat_map(|s| &s.model.effects)
        .map(|e| if let softcontact_contact::Effect::ToolGravity { mass } = *e { mass } else { 0.0 })
        .sum();
    if extra != 0.0 && load.mass > 0.0 {
        let scale = (load.mass + extra) / load.mass;
        load.mass *= scale;
        load.first_moment *= scale;
        load.inertia_origin *= scale;
    }
    load
}

/// The force-control paper's sponge: Azad-Featherstone-like, ≈ 280 N at 5 cm.
pub fn sponge() -> ContactModel {
    ContactModel::new(softcontact_contact::Kind::AzadFeatherstone, 280.0 / 0.05f64.powf(1.5), 1100.0)
        .expect("valid preset")
}

/// The force-control paper's dice: Kelvin-Voigt-like, ≈ 130 N at 7 cm.
pub fn dice() -> ContactModel {
    ContactModel::new(softcontact_contact::Kind::KelvinVoigt, 130.0 / 0.07, 60.0).expect("valid preset")
}

/// The force-control paper's sponge as a real one behaves: the law of [`sponge`] plus what none of the model kinds
/// has — viscoelastic relaxation on two time scales (a fast Maxwell branch that stiffens the foam under
/// 1 Hz pushes but has relaxed by the end of a slow move, and a slow one: creep under held deformation)
/// and a little rate-dependent hysteresis. A model identified under pushes is thus biased for slow
/// moves, as on the real robot.
pub fn lab_sponge() -> ContactModel {
    with_lab_effects(sponge(), [2500.0, 100.0])
}

/// The force-control paper's dice as a real one behaves: the law of [`dice`] plus the effects of [`lab_sponge`].
pub fn lab_dice() -> ContactModel {
    with_lab_effects(dice(), [600.0, 30.0])
}

/// Fast (0.15 s) and slow (5 s) relaxation branches of the given stiffnesses [N/m], and ±2 %
/// hysteresis of the elastic force (full at 5 cm/s).
fn with_lab_effects(mut model: ContactModel, branches: [f64; 2]) -> ContactModel {
    use softcontact_contact::Effect;
    model.effects = vec![
        Effect::ViscoelasticRelaxation { stiffness: branches[0], time_constant: 0.15 },
        Effect::ViscoelasticRelaxation { stiffness: branches[1], time_constant: 5.0 },
        Effect::Hysteresis { fraction: 0.02, velocity_scale: 0.05 },
    ];
    model
}

/// A pose with the hand facing down in front of the robot: A2 = 30°, A3 = −80°, A5 = 70° (the pitches
/// add up to 180°).
pub const DEFAULT_Q: [f64; 7] = [0.0, 30.0 * DEG, 0.0, -80.0 * DEG, 0.0, 70.0 * DEG, 0.0];
const DEG: f64 = std::f64::consts::PI / 180.0;

/// The simulated robot cell.
pub struct Simulator {
    /// The robot as the KRC knows it (the URDF's).
    model: Model,
    data: Data,
    /// The robot as it moves: the model with the hidden payload, if any.
    physics: Model,
    physics_data: Data,
    tool: FrameId,
    sensor_frame: FrameId,
    q: [f64; 7],
    dq: [f64; 7],
    time: f64,
    steps_per_cycle: usize,
    config: SimConfig,
    pub krc: Krc,
    pub surface: Option<Surface>,
    pub sensor: FtSensor,
    rng: SmallRng,
    last_contact: Contact,
    last_torque: [f64; 7],
    jacobian: nalgebra::Matrix6xX<f64>,
}

impl Simulator {
    pub fn new(config: SimConfig) -> Result<Self, SimError> {
        let model = lwr4::model();
        if !(config.step > 0.0 && config.cycle >= config.step) {
            return Err(SimError::Config("step must be > 0 and cycle ≥ step".into()));
        }
        let ratio = config.cycle / config.step;
        if (ratio - ratio.round()).abs() > 1e-9 {
            return Err(SimError::Config(format!(
                "the cycle {} s is not a whole number of steps of {} s",
                config.cycle, config.step
            )));
        }
        if config.initial_q.iter().zip(&model.joints).any(|(q, j)| *q < j.limits.lower || *q > j.limits.upper) {
            return Err(SimError::Config("initial joint positions outside the joint limits".into()));
        }
        let tool = model.frame_id(lwr4::TOOL_FRAME)?;
        let sensor_frame = model.frame_id(lwr4::FT_SENSOR_FRAME)?;
        let surface = config.surface.clone().map(Surface::new).transpose()?;
        let krc = Krc::new(config.krc.clone(), config.initial_q);
        let sensor = FtSensor::new(config.sensor.clone(), sensed_load(config.surface.as_ref()));
        let data = model.data();
        let physics = match &config.payload {
            Some(payload) => payload.carried_by(&model).map_err(|e| SimError::Config(e.to_string()))?,
            None => model.clone(),
        };
        let physics_data = physics.data();
        let mut sim = Self {
            data,
            physics,
            physics_data,
            tool,
            sensor_frame,
            q: config.initial_q,
            dq: [0.0; 7],
            time: 0.0,
            steps_per_cycle: ratio.round() as usize,
            rng: SmallRng::seed_from_u64(config.seed),
            krc,
            surface,
            sensor,
            config,
            model,
            last_contact: Contact::default(),
            last_torque: [0.0; 7],
            jacobian: nalgebra::Matrix6xX::zeros(7),
        };
        // The contact of the initial state (no time passed).
        sim.touch(0.0)?;
        Ok(sim)
    }

    /// The FRI cycle \[s\].
    pub fn krc_cycle(&self) -> f64 {
        self.config.cycle
    }

    pub fn model(&self) -> &Model {
        &self.model
    }
    pub fn time(&self) -> f64 {
        self.time
    }
    pub fn q(&self) -> &[f64; 7] {
        &self.q
    }
    pub fn dq(&self) -> &[f64; 7] {
        &self.dq
    }
    /// The contact at the current state.
    pub fn contact(&self) -> &Contact {
        &self.last_contact
    }
    /// Motor torques of the last step.
    pub fn applied_torque(&self) -> &[f64; 7] {
        &self.last_torque
    }

    /// Pose of the hand's sole centre in the world.
    pub fn tool_pose(&mut self) -> Isometry3<f64> {
        self.model.forward_kinematics(&mut self.data, &self.q);
        self.model.frame_pose(&self.data, self.tool)
    }

    /// Puts the arm at rest at q (tests and scenario set-up).
    pub fn set_state(&mut self, q: [f64; 7], dq: [f64; 7]) {
        self.q = q;
        self.dq = dq;
        self.krc.hold_at(q);
    }

    /// The FRI measurement the KRC sends now (advances the KRC's sequence counter).
    pub fn measurement(&mut self) -> fri::Measurement {
        self.krc.measurement(
            &self.model,
            &mut self.data,
            self.tool,
            &self.q,
            &self.last_torque,
            &self.last_contact.force,
            self.time,
            &mut self.rng,
        )
    }

    /// A command datagram arriving from the remote.
    pub fn command(&mut self, cmd: &fri::Command) -> Option<KrcEvent> {
        self.krc.receive(cmd, &self.q)
    }

    /// The RDT record the F/T sensor sends now.
    pub fn ft_record(&mut self) -> rdt::Record {
        self.model.forward_kinematics(&mut self.data, &self.q);
        let sensor_pose = self.model.frame_pose(&self.data, self.sensor_frame);
        let tool_pose = self.model.frame_pose(&self.data, self.tool);
        self.sensor.record(
            &sensor_pose,
            &tool_pose,
            &self.last_contact.sensed_force,
            self.model.gravity,
            self.time,
            &mut self.rng,
        )
    }

    /// RDT 0x0042 to the simulated box: it biases on the reading of this moment.
    pub fn ft_set_bias(&mut self) {
        self.model.forward_kinematics(&mut self.data, &self.q);
        let sensor_pose = self.model.frame_pose(&self.data, self.sensor_frame);
        let tool_pose = self.model.frame_pose(&self.data, self.tool);
        self.sensor.set_bias(
            &sensor_pose,
            &tool_pose,
            &self.last_contact.sensed_force,
            self.model.gravity,
            self.time,
            &mut self.rng,
        )
    }

    /// Advances one FRI cycle: the KRC closes its cycle (quality, watchdog), then the arm moves under
    /// the KRC's torques and the surface's force.
    pub fn step_cycle(&mut self) -> Result<Option<KrcEvent>, SimError> {
        let event = self.krc.end_of_cycle();
        for _ in 0..self.steps_per_cycle {
            self.step()?;
        }
        Ok(event)
    }

    /// The contact at the current state, the surface's memory advanced by dt (the time since the last
    /// state): what the F/T sensor reads now and what acts on the arm during the next step.
    fn touch(&mut self, dt: f64) -> Result<(), SimError> {
        self.model.forward_kinematics(&mut self.data, &self.q);
        let pose = self.model.frame_pose(&self.data, self.tool);
        let velocity = self.model.frame_velocity(&mut self.data, &self.q, &self.dq, self.tool); // FK reused
        let tool_velocity = Vector3::new(velocity[0], velocity[1], velocity[2]);
        self.last_contact = match self.surface.as_mut() {
            Some(s) => s.contact(&pose.translation.vector, &tool_velocity, dt)?,
            None => Contact::default(),
        };
        Ok(())
    }

    /// The motor torques that hold the arm still against gravity and the contact force: what the joint
    /// torque sensors read under the brakes or the position controller.
    fn holding_torque(&mut self) -> [f64; 7] {
        let g = self.physics.gravity_torques(&mut self.physics_data, &self.q);
        self.model.forward_kinematics(&mut self.data, &self.q);
        let jacobian = &mut self.jacobian;
        self.model.frame_jacobian(&self.data, self.tool, softcontact_dynamics::Axes::World, jacobian);
        let f = self.last_contact.force;
        std::array::from_fn(|j| g[j] - (0..3).map(|r| jacobian[(r, j)] * f[r]).sum::<f64>())
    }

    fn step(&mut self) -> Result<(), SimError> {
        let h = self.config.step;
        // The contact at the current state is `last_contact`; after the step, the new state's.
        let mut tau = match self.krc.drive(&self.model, &mut self.data, &self.q, &self.dq) {
            Drive::Torque(tau) => tau,
            Drive::Brakes => {
                self.dq = [0.0; 7];
                self.last_torque = self.holding_torque();
                self.time += h;
                return self.touch(h);
            }
            Drive::Position(target) => {
                // As stiff as the arm's own position controller: the joints go where commanded, at most at
                // half their velocity limit, whatever the surface pushes.
                for (i, j) in self.model.joints.iter().enumerate() {
                    let reach = 0.5 * j.limits.velocity * h;
                    let step = (target[i].clamp(j.limits.lower, j.limits.upper) - self.q[i]).clamp(-reach, reach);
                    self.q[i] += step;
                    self.dq[i] = step / h;
                }
                self.last_torque = self.holding_torque();
                self.time += h;
                return self.touch(h);
            }
        };
        for (i, j) in self.model.joints.iter().enumerate() {
            tau[i] = tau[i].clamp(-j.limits.effort, j.limits.effort);
        }
        self.last_torque = tau;
        let mut applied = tau;
        if let Some(f) = &self.config.friction {
            for (i, t) in applied.iter_mut().enumerate() {
                *t -= f.torque(i, self.dq[i]);
            }
        }
        let wrench = ExternalWrench { frame: self.tool, force: self.last_contact.force, torque: Vector3::zeros() };
        let ddq = self.physics.forward_dynamics(&mut self.physics_data, &self.q, &self.dq, &applied, Some(&wrench))?;
        for i in 0..7 {
            self.dq[i] += h * ddq[i];
            self.q[i] += h * self.dq[i];
        }
        if let Some(joint) = self.model.joints.iter().enumerate().find(|(i, j)| self.dq[*i].abs() > j.limits.velocity) {
            // The KRC's speed limit: fall back to monitor mode and brake.
            self.krc.trip(format!("joint {} exceeded its velocity limit", joint.1.name), self.q);
            self.dq = [0.0; 7];
        }
        self.time += h;
        self.touch(h)
    }
}
