//! The demo's recording: what the graph's nodes would publish, written to ROS 2 MCAP as the run goes
//! (stamps: the simulated time after the wall-clock time the demo started).

use softcontact_msgs::topics;
use std::path::Path;

use softcontact_bag::BagWriter;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::softcontact_msgs::ForceCommand;
use softcontact_nodes::contact_estimator::ModelOut;
use softcontact_nodes::messages;
use softcontact_simcell::cell::Tick;

use super::experiment::Observer;

struct Channels {
    joint_states: u16,
    ee_pose: u16,
    ee_twist: u16,
    wrench: u16,
    tare: u16,
    controller_state: u16,
    estimator_state: u16,
    model: u16,
    force_command: u16,
}

pub struct Recorder {
    writer: BagWriter,
    channels: Channels,
    /// Nanoseconds since the epoch at simulated time zero.
    epoch: u64,
    names: Vec<String>,
    ticks: u64,
}

impl Recorder {
    pub fn create(path: &Path, epoch: u64) -> anyhow::Result<Self> {
        let _ = std::fs::remove_file(path);
        let mut w = BagWriter::create(path)?;
        let tf_static = w.add(&topics::TF_STATIC)?;
        let channels = Channels {
            joint_states: w.add(&topics::JOINT_STATES)?,
            ee_pose: w.add(&topics::EE_POSE)?,
            ee_twist: w.add(&topics::EE_TWIST)?,
            wrench: w.add(&topics::WRENCH)?,
            tare: w.add(&topics::TARE)?,
            controller_state: w.add(&topics::CONTROLLER_STATE)?,
            estimator_state: w.add(&topics::CONTACT_STATE)?,
            model: w.add(&topics::CONTACT_MODEL)?,
            force_command: w.add(&topics::FORCE_COMMAND)?,
        };
        w.write(tf_static, epoch, &messages::tool_to_sensor_static(stamp(epoch)))?;
        let model = softcontact_dynamics::lwr4::model();
        Ok(Self { writer: w, channels, epoch, names: model.joints.iter().map(|j| j.name.clone()).collect(), ticks: 0 })
    }

    pub fn finish(self) -> anyhow::Result<softcontact_bag::WriteStats> {
        Ok(self.writer.finish()?)
    }

    fn at(&self, time: f64) -> u64 {
        self.epoch + (time * 1e9).round() as u64
    }
}

fn stamp(ns: u64) -> Time {
    Time { sec: (ns / 1_000_000_000) as i32, nanosec: (ns % 1_000_000_000) as u32 }
}

impl Observer for Recorder {
    fn tick(&mut self, tick: &Tick) -> anyhow::Result<()> {
        let ns = self.at(tick.time);
        let t = stamp(ns);
        let c = &self.channels;
        let m = tick.driver.messages(&self.names, &tick.tool, t);
        self.writer.write(c.joint_states, ns, &m.joint_state)?;
        self.writer.write(c.ee_pose, ns, &m.ee_pose)?;
        self.writer.write(c.ee_twist, ns, &m.ee_twist)?;
        if let Some(bias) = tick.tare {
            self.writer.write(c.tare, ns, &messages::wrench(&bias, t))?;
        }
        if let Some(w) = tick.ft.compensated.filter(|_| tick.tared && !tick.ft.invalid) {
            self.writer.write(c.wrench, ns, &messages::wrench(&w, t))?;
        }
        // The nodes' state topics at their 100 Hz.
        if self.ticks.is_multiple_of(10) {
            self.writer.write(
                c.controller_state,
                ns,
                &softcontact_nodes::messages::controller_state(&tick.controller, t),
            )?;
            self.writer.write(c.estimator_state, ns, &tick.estimator.to_msg(t))?;
        }
        self.ticks += 1;
        Ok(())
    }

    fn model(&mut self, time: f64, model: &ModelOut) -> anyhow::Result<()> {
        let ns = self.at(time);
        self.writer.write(self.channels.model, ns, &model.to_msg(messages::header("world", stamp(ns))))?;
        Ok(())
    }

    fn force_command(&mut self, time: f64, force: f64, duration: f64) -> anyhow::Result<()> {
        self.writer.write(self.channels.force_command, self.at(time), &ForceCommand { force, duration })?;
        Ok(())
    }
}
