//! The robot cell in-process, in lockstep with the simulator: the very driver and F/T node code
//! exchanges real FRI and RDT bytes with the simulated arm and sensor each 1 ms cycle, the deformation
//! controller closes the loop and the contact estimator watches — without DDS, clocks or threads, so runs
//! are fast and deterministic (tests, the demo). The loop runs as ros2_control runs it, read → update →
//! write on one thread: each FRI measurement is answered with the torque the controller computed for that
//! very measurement (`LwrDriver::measure`, `set_command`, `answer`), from the F/T sensor's newest record.

use nalgebra::{UnitQuaternion, Vector3};
use softcontact_dynamics::{Data, FrameId, Model, lwr4};
use softcontact_sim::{SimConfig, SimError, Simulator};
use softcontact_wire::fri::InterfaceState;

use crate::contact_estimator::{ContactEstimatorNode, ContactStateOut};
use crate::deformation_controller::{ControlError, ControllerState, DeformationController};
use crate::ft_sensor::{FtConfig, FtOutput, FtSensorNode};
use crate::lwr_driver::{DriverConfig, DriverError, DriverOutput, LwrDriver, Measured};

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
    /// Simulated time [s].
    pub time: f64,
    pub driver: DriverOutput,
    pub ft: FtOutput,
    /// The F/T node has tared: it publishes /ft_sensor/wrench.
    pub tared: bool,
    /// The bias of a tare taken since the previous tick (the node publishes it on /ft_sensor/tare).
    pub tare: Option<[f64; 6]>,
    /// The contact force on the hand in the world, from the sensor (zero until tared) [N].
    pub force_world: Vector3<f64>,
    pub controller: ControllerState,
    /// The torque sent to the driver; `None` when the controller's tick failed and the driver was asked
    /// to hold (the error says why).
    pub torque: Option<[f64; 7]>,
    pub refused: Option<ControlError>,
    pub estimator: ContactStateOut,
}

/// The simulated cell and the nodes, wired as `launch-scripts/sim.sh` wires their processes.
pub struct Cell {
    pub sim: Simulator,
    pub driver: LwrDriver,
    pub ft: FtSensorNode,
    pub controller: DeformationController,
    pub estimator: ContactEstimatorNode,
    normal: Vector3<f64>,
    model: Model,
    data: Data,
    sensor: FrameId,
    orientation: Option<UnitQuaternion<f64>>,
    /// Command cycles before the F/T node tares itself (the ft_sensor node's `tare_after`).
    tare_after: usize,
    tared: bool,
    pending_tare: Option<[f64; 6]>,
    commanding: usize,
}

impl Cell {
    /// The cell with the F/T node set up for the LWR's hand (tared after 100 command cycles, as the
    /// ft_sensor node does at start-up, with the node's checks) and the estimator and controller given.
    pub fn new(
        sim: SimConfig,
        controller: DeformationController,
        estimator: ContactEstimatorNode,
        normal: Vector3<f64>,
    ) -> Result<Self, CellError> {
        let model = lwr4::model();
        let ft = FtSensorNode::new(FtConfig {
            calibration: sim.sensor.calibration,
            tool: lwr4::tool_load(),
            gravity: Vector3::new(0.0, 0.0, -9.81),
            low_pass: None,
            sample_rate: 1000.0,
        })
        .map_err(CellError::Ft)?;
        Ok(Self {
            sim: Simulator::new(sim)?,
            driver: LwrDriver::new(DriverConfig::default()),
            ft,
            controller,
            estimator,
            normal: normal.try_normalize(1e-9).unwrap_or_else(|| Vector3::new(0.0, 0.0, -1.0)),
            data: model.data(),
            sensor: model.frame_id(lwr4::FT_SENSOR_FRAME).map_err(ControlError::from)?,
            model,
            orientation: None,
            tare_after: 100,
            tared: false,
            pending_tare: None,
            commanding: 0,
        })
    }

    /// Software tare now, as the /ft_sensor/bias service does it: refused (with the reason) when the
    /// hand is in contact or moving, or the reading is unsteady.
    pub fn tare(&mut self) -> Result<(), CellError> {
        self.pending_tare = Some(self.ft.checked_tare(self.orientation.as_ref()).map_err(CellError::Ft)?);
        self.tared = true;
        Ok(())
    }

    /// One 1 ms cycle through the wire formats, read → update → write as one process runs it: the F/T
    /// node reads the sensor's newest record, the driver reads the KRC's measurement, the controller
    /// computes the torque for that very measurement and the driver answers with it (or holds); then the
    /// simulator moves. `None` until the KRC commands.
    pub fn cycle(&mut self) -> Result<Option<Tick>, CellError> {
        let time = self.sim.time();
        let record = self.sim.ft_record().encode();
        let measured = self.driver.measure(&self.sim.measurement().encode())?;
        let out = &measured.output;
        // /lwr/ee_pose, which the F/T node's tare checks for motion.
        self.ft.observe_tool_pose(&out.tool_pose);
        self.model.forward_kinematics(&mut self.data, &out.q);
        let orientation = self.model.frame_pose(&self.data, self.sensor).rotation;
        self.orientation = Some(orientation);
        let ft = self.ft.handle(&record, Some(&orientation)).map_err(|e| CellError::Ft(e.to_string()))?;
        if out.state != InterfaceState::Command {
            self.write(measured)?;
            return Ok(None);
        }
        self.commanding += 1;
        // The start-up tare, retried every `tare_after` cycles while refused, as the node retries it.
        if self.commanding.is_multiple_of(self.tare_after) && !self.tared {
            let _refused = self.tare();
        }
        let force_world = match ft.compensated.filter(|_| self.tared && !ft.invalid) {
            Some(c) => orientation * Vector3::new(c[0], c[1], c[2]),
            None => Vector3::zeros(),
        };
        let f = (-force_world.dot(&self.normal)).max(0.0);
        self.controller.follow_session(Some(out.session), true, self.sim.krc_cycle());
        // Until the F/T node has tared it publishes no /ft_sensor/wrench, and an invalid sample
        // (saturated, an error bit) is withheld from it: no tick, and the driver holds. A failed tick
        // also holds: never an older torque.
        let withheld = !self.tared || ft.invalid;
        let tick = (!withheld).then(|| self.controller.tick(&out.q, &out.dq, f, &force_world));
        let (torque, controller, refused) = match tick {
            None => (None, ControllerState { f, ..Default::default() }, None),
            Some(Ok((tau, state))) => (Some(tau), state, None),
            Some(Err(e)) => (None, ControllerState { f, ..Default::default() }, Some(e)),
        };
        let v = out.tool_twist;
        let estimator =
            self.estimator.update(time, &out.tool_pose.translation.vector, &Vector3::new(v[0], v[1], v[2]), f)?;
        match torque {
            // A refused torque (not 7 finite values) clears the command: the driver holds.
            Some(tau) => self.driver.set_command(&tau).map_or((), |_| ()),
            None => self.driver.clear_command(),
        }
        let driver = self.write(measured)?;
        Ok(Some(Tick {
            time,
            driver,
            ft,
            tared: self.tared,
            tare: self.pending_tare.take(),
            force_world,
            controller,
            torque,
            refused,
            estimator,
        }))
    }

    /// The driver's answer to the KRC, and the simulator's cycle under it.
    fn write(&mut self, measured: Measured) -> Result<DriverOutput, CellError> {
        let (reply, driver) = self.driver.answer(measured);
        self.sim.command(&reply);
        self.sim.step_cycle()?;
        Ok(driver)
    }

    /// Cycles until the KRC commands and the F/T node has tared (at most `limit` cycles).
    pub fn start(&mut self, limit: usize) -> Result<Tick, CellError> {
        for _ in 0..limit {
            if let Some(t) = self.cycle()?.filter(|_| self.tared) {
                return Ok(t);
            }
        }
        Err(CellError::Ft(format!("no tared command cycle within {limit} cycles")))
    }
}
