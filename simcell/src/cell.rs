//! The robot cell in-process, in lockstep with the simulator: the very driver and F/T node code
//! exchanges real FRI and RDT bytes with the simulated arm and sensor each 1 ms cycle, the deformation
//! controller closes the loop and the contact estimator watches — without DDS, clocks or threads, so runs
//! are fast and deterministic (tests, the demo). The loop runs as ros2_control runs it, read → update →
//! write on one thread: each FRI measurement is answered with the torque the controller computed for that
//! very measurement (`LwrDriver::measure`, `set_command`, `answer`), from the F/T sensor's newest record.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use softcontact_dynamics::FrameMotion;
use softcontact_sim::{SimConfig, SimError, Simulator};
use softcontact_wire::WireError;

use softcontact_nodes::contact_estimator::{ContactEstimatorNode, ContactStateOut};
use softcontact_nodes::deformation_controller::{
    self, ControlError, ControllerNode, ControllerState, DeformationController, JointSample, Reply,
};
use softcontact_nodes::ft_sensor::{self, FtConfig, FtOutput, FtSensorNode, StartupTare};
use softcontact_nodes::lwr_driver::{DriverError, DriverOutput, LwrDriver, Params as DriverParams};

#[derive(Debug, thiserror::Error)]
pub enum CellError {
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("LWR driver: {0}")]
    Driver(#[from] DriverError),
    #[error("F/T node: {0}")]
    Ft(String),
    #[error("controller: {0}")]
    Control(#[from] ControlError),
    #[error("estimator: {0}")]
    Estimator(#[from] softcontact_contact::ContactError),
}

/// What one cycle produced, once the KRC is in command mode.
#[derive(Debug, Clone)]
pub struct Tick {
    /// Simulated time \[s\].
    pub time: f64,
    pub driver: DriverOutput,
    /// The tool's pose and twist at the measurement.
    pub tool: FrameMotion,
    pub ft: FtOutput,
    /// The F/T node has tared: it publishes /ft_sensor/wrench.
    pub tared: bool,
    /// The bias of a tare taken since the previous tick (the node publishes it on /ft_sensor/tare).
    pub tare: Option<[f64; 6]>,
    /// The contact force on the hand in the world, from the sensor (zero until tared) \[N\].
    pub force_world: Vector3<f64>,
    pub controller: ControllerState,
    /// The torque sent to the driver; `None` when the controller's tick failed and the driver was asked
    /// to hold (the error says why).
    pub torque: Option<[f64; 7]>,
    pub refused: Option<ControlError>,
    pub estimator: ContactStateOut,
}

/// The simulated KRC and Net F/T box wired to the product's driver and F/T node, one 1 ms FRI cycle at
/// a time, read → update → write: the one place the lockstep cycle is written. The controller's
/// [`Cell`] and the CLI's loading-paths stage are its two updates; on the robot the same driver calls
/// run in `udp::FriClient::cycle_with`.
pub struct Lockstep {
    pub sim: Simulator,
    pub driver: LwrDriver,
    pub ft: FtSensorNode,
}

/// One cycle as an update sees it: the measurement the driver read, the sensor's newest record, and the
/// driver to hand the command to ([`LwrDriver::set_command`]; none set: the driver holds).
pub struct Cycle<'a> {
    /// Simulated time at the measurement \[s\].
    pub time: f64,
    pub measured: &'a DriverOutput,
    pub driver: &'a mut LwrDriver,
    pub ft: &'a mut FtSensorNode,
    record: &'a [u8],
}

impl Cycle<'_> {
    /// The F/T node's reading of this cycle's record, handed the tool's pose (/lwr/ee_pose, which its
    /// tare checks for motion) and the sensor's orientation in the world (its tf lookup).
    pub fn read_ft(&mut self, tool: &Isometry3<f64>, orientation: &UnitQuaternion<f64>) -> Result<FtOutput, WireError> {
        self.ft.observe_tool_pose(tool);
        self.ft.handle(self.record, Some(orientation))
    }
}

impl Lockstep {
    /// One cycle: the sensor's record and the KRC's measurement are read, `update` sets the command for
    /// that very measurement, the driver's answer goes to the simulated KRC and the simulator moves one
    /// cycle under it. An update's error leaves the measurement unanswered and the simulator where it
    /// was. Returns the update's value and the driver's output as answered.
    pub fn cycle<T, E>(&mut self, update: impl FnOnce(Cycle<'_>) -> Result<T, E>) -> Result<(T, DriverOutput), E>
    where
        E: From<DriverError> + From<SimError>,
    {
        let time = self.sim.time();
        let record = self.sim.ft_record().encode();
        let measured = self.driver.measure(&self.sim.measurement().encode())?;
        let cycle =
            Cycle { time, measured: &measured.output, driver: &mut self.driver, ft: &mut self.ft, record: &record };
        let value = update(cycle)?;
        let (reply, answered) = self.driver.answer(measured);
        self.sim.command(&reply);
        self.sim.step_cycle()?;
        Ok((value, answered))
    }
}

/// The simulated cell and the nodes, wired as `launch-scripts/sim.sh` wires them: the very node
/// structs and policies of the graph (the controller's [`ControllerNode`], the F/T node's start-up tare),
/// run on the simulator's clock.
pub struct Cell {
    pub lockstep: Lockstep,
    pub controller: ControllerNode,
    pub estimator: ContactEstimatorNode,
    orientation: Option<UnitQuaternion<f64>>,
    startup_tare: StartupTare,
    pending_tare: Option<[f64; 6]>,
    driver_fault: Option<softcontact_nodes::lwr_driver::Fault>,
}

impl Cell {
    /// The cell with the F/T node set up for the LWR's hand (its parameters' defaults: tared at start-up
    /// after `tare_after`, with the node's checks), the estimator, and the controller node around `law`
    /// (the node's default policy, the law's normal).
    pub fn new(sim: SimConfig, law: DeformationController, estimator: ContactEstimatorNode) -> Result<Self, CellError> {
        let ft_params = ft_sensor::Params::default();
        let ft = FtSensorNode::new(FtConfig::lwr4(sim.sensor.calibration))
            .map_err(CellError::Ft)?
            .with_tare_policy(ft_params.tare_policy());
        let params = deformation_controller::Params {
            normal: law.config().normal.into(),
            restart_after: law.config().restart_after,
            ..Default::default()
        };
        Ok(Self {
            lockstep: Lockstep { sim: Simulator::new(sim)?, driver: LwrDriver::new(DriverParams::default()), ft },
            controller: ControllerNode::new(&params, law)?,
            estimator,
            orientation: None,
            startup_tare: StartupTare::new(ft_params.tare_after),
            pending_tare: None,
            driver_fault: None,
        })
    }

    /// Software tare now, as the /ft_sensor/bias service does it: refused (with the reason) when the
    /// hand is in contact or moving, or the reading is unsteady.
    pub fn tare(&mut self) -> Result<(), CellError> {
        let bias = self.lockstep.ft.checked_tare(self.orientation.as_ref()).map_err(CellError::Ft)?;
        self.pending_tare = Some(bias);
        self.startup_tare.taken();
        Ok(())
    }

    /// One 1 ms cycle through the wire formats, as one process runs it: the F/T node reads the sensor's
    /// newest record, the driver reads the KRC's measurement, the controller node computes the torque
    /// for that very measurement and the driver answers with it (or holds); then the simulator moves.
    /// `None` until the KRC commands.
    pub fn cycle(&mut self) -> Result<Option<Tick>, CellError> {
        let Self { lockstep, controller, estimator, orientation, startup_tare, pending_tare, driver_fault } = self;
        let (tick, answered) = lockstep.cycle(|mut c| -> Result<_, CellError> {
            let (time, out) = (c.time, c.measured);
            // The cycle's one kinematics pass, the law's (its tick reuses it).
            let tool = controller.law.tool_motion(&out.q, &out.dq);
            let sensor = controller.geometry().sensor_rotation(&tool.pose.rotation);
            *orientation = Some(sensor);
            let ft = c.read_ft(&tool.pose, &sensor).map_err(|e| CellError::Ft(e.to_string()))?;
            if let Some(Ok(bias)) = startup_tare.poll(c.ft, &sensor, time) {
                *pending_tare = Some(bias);
            }
            // /ft_sensor/wrench: published once tared, an invalid sample (saturated, an error bit) withheld.
            match ft.compensated.filter(|_| startup_tare.tared() && !ft.invalid) {
                Some(f) => controller.on_force(time, Vector3::new(f[0], f[1], f[2]), time),
                None => controller.force_withheld(),
            }
            if c.driver.fault() != *driver_fault {
                *driver_fault = c.driver.fault();
                controller.on_driver_fault(driver_fault.map(|f| f.to_string()));
            }
            let commanding = out.torque_mode();
            let joint_state = JointSample { stamp: time, session: Some(out.session), commanding, q: out.q, dq: out.dq };
            controller.on_external_torque(time, &out.external_torque);
            let step = controller.on_joint_state(&joint_state, time);
            if !commanding {
                return Ok(None);
            }
            let f = controller.geometry().normal_force(&step.force_world);
            let estimate = estimator.update(time, &tool.pose.translation.vector, &tool.linear(), f)?;
            // On the FRI thread nothing is late: anything but a torque for this measurement holds at once.
            let (torque, refused) = match step.reply {
                Reply::Torque(tau) => (Some(tau), None),
                Reply::Hold(e) => (None, Some(e)),
                Reply::Nothing(_) => (None, None),
            };
            match torque {
                // A refused torque (not 7 finite values) clears the command: the driver holds.
                Some(tau) => c.driver.set_command(&tau).map_or((), |_| ()),
                None => c.driver.clear_command(),
            }
            if pending_tare.is_some() {
                controller.law.sensor_tared();
            }
            Ok(Some(Tick {
                time,
                // Replaced by the output as answered (`holding` decided) below.
                driver: out.clone(),
                tool,
                ft,
                tared: startup_tare.tared(),
                tare: pending_tare.take(),
                force_world: step.force_world,
                controller: ControllerState { f, ..step.state },
                torque,
                refused,
                estimator: estimate,
            }))
        })?;
        Ok(tick.map(|t| Tick { driver: answered, ..t }))
    }

    /// Cycles until the KRC commands and the F/T node has tared (at most `limit` cycles).
    pub fn start(&mut self, limit: usize) -> Result<Tick, CellError> {
        for _ in 0..limit {
            if let Some(t) = self.cycle()?.filter(|t| t.tared) {
                return Ok(t);
            }
        }
        Err(CellError::Ft(format!("no tared command cycle within {limit} cycles")))
    }
}
