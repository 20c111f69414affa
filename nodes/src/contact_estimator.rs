//! The contact estimator as a node struct: from the tool's position and velocity and the measured
//! normal force it detects contact, keeps (z, ż, f) samples every `sample_period` in the sliding window
//! (seed 001: 1200 samples at 10 ms), and on `refit` chooses the best kind by cross-validated fitness
//! and estimates where the surface really is (the onset threshold fires late on a soft surface).

use nalgebra::Vector3;
use softcontact_contact::{
    ContactError, ContactModel, Estimate, FitConfig, OnsetConfig, OnsetDetector, OnsetEvent, Sample, WindowEstimator,
    estimate_contact_offset,
};

#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorConfig {
    /// Contact direction n in the world.
    pub normal: Vector3<f64>,
    /// Time between window samples [s].
    pub sample_period: f64,
    /// Samples in the window.
    pub window: usize,
    pub onset: OnsetConfig,
    pub fit: FitConfig,
    /// Where to look for the true surface relative to the onset position, along n [m].
    pub offset_range: (f64, f64),
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            normal: Vector3::new(0.0, 0.0, -1.0),
            sample_period: 0.01,
            window: 1200,
            onset: OnsetConfig::default(),
            fit: FitConfig::default(),
            offset_range: (-0.01, 0.01),
        }
    }
}

/// /contact_estimator/state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ContactStateOut {
    pub deformation: f64,
    pub deformation_rate: f64,
    pub normal_force: f64,
    pub in_contact: bool,
}

/// /contact_estimator/model.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelOut {
    /// The chosen model, fitted at the estimated surface position.
    pub model: ContactModel,
    /// The surface lies at d + offset·n, d the onset position.
    pub offset: f64,
    /// The surface position in the world.
    pub contact_position: Vector3<f64>,
    /// Every candidate's cross-validated fit (kind choice).
    pub estimate: Estimate,
    pub window_fill: f64,
    pub stiffness_excited: bool,
    pub damping_excited: bool,
}

pub struct ContactEstimatorNode {
    config: EstimatorConfig,
    normal: Vector3<f64>,
    onset: OnsetDetector,
    contact: Option<(f64, Vector3<f64>)>,
    window: WindowEstimator,
    next_sample: f64,
}

impl ContactEstimatorNode {
    pub fn new(config: EstimatorConfig) -> Result<Self, ContactError> {
        let normal = config
            .normal
            .try_normalize(1e-9)
            .ok_or_else(|| ContactError::InvalidConfig("the contact normal must not be zero".into()))?;
        if !(config.sample_period.is_finite() && config.sample_period > 0.0) {
            return Err(ContactError::InvalidConfig("sample period must be positive".into()));
        }
        Ok(Self {
            onset: OnsetDetector::new(config.onset)?,
            window: WindowEstimator::new(config.window, config.fit)?,
            contact: None,
            next_sample: 0.0,
            normal,
            config,
        })
    }

    /// One reading at time t [s]: tool position and velocity in the world, normal force f = −F·n.
    pub fn update(
        &mut self,
        t: f64,
        position: &Vector3<f64>,
        velocity: &Vector3<f64>,
        normal_force: f64,
    ) -> Result<ContactStateOut, ContactError> {
        let along = position.dot(&self.normal);
        if let Some(event) = self.onset.update(along, normal_force)? {
            match event {
                OnsetEvent::Contact { position: level } if self.contact.is_none() => {
                    self.contact = Some((level, position - (along - level) * self.normal));
                }
                _ => {}
            }
        }
        let Some((level, _)) = self.contact else {
            return Ok(ContactStateOut { normal_force, ..Default::default() });
        };
        let out = ContactStateOut {
            deformation: along - level,
            deformation_rate: velocity.dot(&self.normal),
            normal_force,
            in_contact: self.onset.in_contact(),
        };
        // In-contact samples only: where the surface has let go, the law says nothing.
        if t >= self.next_sample {
            self.next_sample = t + self.config.sample_period;
            if out.in_contact && normal_force > self.config.onset.threshold {
                self.window.push(Sample::new(out.deformation, out.deformation_rate, normal_force)?)?;
            }
        }
        Ok(out)
    }

    /// Refits every kind over the window, chooses one, and places the surface.
    pub fn refit(&mut self) -> Result<ModelOut, ContactError> {
        let (_, onset_point) = self.contact.ok_or(ContactError::NotEnoughData { kind: "a contact" })?;
        let estimate = self.window.refit()?;
        let chosen = estimate.selected_fit().clone();
        let samples: Vec<Sample> = self.window.samples().copied().collect();
        let prior = Some((chosen.stiffness, chosen.damping));
        let (offset, fit) =
            estimate_contact_offset(&samples, chosen.exponents, self.config.offset_range, prior, &self.config.fit)?;
        Ok(ModelOut {
            model: fit.model()?,
            offset,
            contact_position: onset_point + offset * self.normal,
            window_fill: self.window.len() as f64 / self.window.capacity() as f64,
            stiffness_excited: !chosen.stiffness_held,
            damping_excited: !chosen.damping_held,
            estimate,
        })
    }
}
