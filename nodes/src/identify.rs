//! Offline identification (`softcontact identify`): the contact estimator run over a whole recording
//! instead of a sliding window, with the frames the recording carries.

use nalgebra::Vector3;
use softcontact_contact::{ContactError, Kind};
use softcontact_msgs::geometry_msgs::{PoseStamped, TwistStamped, WrenchStamped};
use softcontact_msgs::tf2_msgs::TFMessage;

use crate::contact_estimator::{ContactEstimatorNode, EstimatorConfig, ForcePairing, ModelOut};
use crate::geometry;

/// Where the sensor's rotation in the tool frame came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FramesFrom {
    TfStatic,
    Urdf,
}

/// Feeds a recording's messages, in the order they were recorded, to the estimator.
pub struct Identifier {
    estimator: ContactEstimatorNode,
    pairing: ForcePairing,
    frames: FramesFrom,
    tool_frame: String,
    pub readings: u64,
    pub unpaired: u64,
    pub contact_time: Option<f64>,
    first_time: Option<f64>,
}

/// The result: every candidate's fit (cross-validated), the chosen model and the surface position.
#[derive(Debug, Clone)]
pub struct Identification {
    pub model: ModelOut,
    pub frames: FramesFrom,
    pub readings: u64,
    pub unpaired: u64,
    pub samples: usize,
    /// Seconds from the first force reading to the onset.
    pub contact_time: f64,
}

impl Identifier {
    /// `config.window` bounds the samples kept: give it at least the recording's duration over
    /// `config.sample_period` to fit every contact sample.
    pub fn new(config: EstimatorConfig, stale_after: f64) -> anyhow::Result<Self> {
        let normal = config.normal;
        Ok(Self {
            estimator: ContactEstimatorNode::new(config)?,
            pairing: ForcePairing::new(ForcePairing::urdf_tool_to_sensor()?, normal, stale_after),
            frames: FramesFrom::Urdf,
            tool_frame: softcontact_dynamics::lwr4::TOOL_FRAME.into(),
            readings: 0,
            unpaired: 0,
            contact_time: None,
            first_time: None,
        })
    }

    /// /tf_static: the sensor frame's rotation in the tool frame replaces the URDF's when it is there.
    pub fn tf_static(&mut self, msg: &TFMessage) {
        let sensor = softcontact_dynamics::lwr4::FT_SENSOR_FRAME;
        if let Some(r) = geometry::static_rotation(&[msg], &self.tool_frame, sensor) {
            self.pairing.tool_to_sensor = r;
            self.frames = FramesFrom::TfStatic;
        }
    }

    pub fn pose(&mut self, msg: &PoseStamped) {
        let (position, rotation) = geometry::pose_of(&msg.pose);
        self.pairing.pose(msg.header.stamp.as_secs_f64(), position, rotation);
    }

    pub fn twist(&mut self, msg: &TwistStamped) {
        self.pairing.twist(geometry::vector_of(&msg.twist.linear));
    }

    pub fn wrench(&mut self, msg: &WrenchStamped) -> Result<(), ContactError> {
        let t = msg.header.stamp.as_secs_f64();
        self.first_time.get_or_insert(t);
        let Some(p) = self.pairing.force(t, geometry::vector_of(&msg.wrench.force)) else {
            self.unpaired += 1;
            return Ok(());
        };
        self.readings += 1;
        let out = self.estimator.update(t, &p.position, &p.velocity, p.normal_force)?;
        if out.in_contact && self.contact_time.is_none() {
            self.contact_time = Some(t);
        }
        Ok(())
    }

    /// Fits every candidate kind over all in-contact samples.
    pub fn finish(mut self) -> Result<Identification, ContactError> {
        let contact_time = self
            .contact_time
            .ok_or(ContactError::NotEnoughData { kind: "a contact (force above the onset threshold)" })?;
        let samples = self.estimator.samples();
        let model = self.estimator.refit()?;
        Ok(Identification {
            model,
            frames: self.frames,
            readings: self.readings,
            unpaired: self.unpaired,
            samples,
            contact_time: contact_time - self.first_time.unwrap_or(contact_time),
        })
    }
}

impl Identification {
    pub fn selected(&self) -> Kind {
        self.model.estimate.selected
    }

    pub fn contact_position(&self) -> Vector3<f64> {
        self.model.contact_position
    }
}
