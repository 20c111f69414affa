//! The contact estimator as a node struct: from the tool's position and velocity and the measured
//! normal force it detects contact, keeps (z, ż, f) samples every `sample_period` in the sliding window
//! (the force-control paper: 1200 samples at 10 ms), and on `refit` chooses the best kind by cross-validated fitness
//! and estimates where the surface really is (the onset threshold fires late on a soft surface).

pub mod component;
pub mod identify;
mod pairing;
mod params;

pub use pairing::{ForcePairing, MAX_READABLE_FORCE, Paired, Unpaired};
pub use params::Params;

use nalgebra::Vector3;

use crate::geometry::ContactGeometry;
use softcontact_contact::{
    ContactError, ContactModel, Effect, Estimate, FitConfig, OnsetConfig, OnsetDetector, OnsetEvent, Sample,
    TimedSample, WindowEstimator, estimate_contact_offset, fit_with_effects, fit_with_effects_at,
};

#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorConfig {
    /// Contact direction n in the world.
    pub normal: Vector3<f64>,
    /// Time between window samples \[s\].
    pub sample_period: f64,
    /// Samples in the window.
    pub window: usize,
    pub onset: OnsetConfig,
    pub fit: FitConfig,
    /// Where to look for the true surface relative to the onset position, along n \[m\].
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
    /// The contact direction (eqs. 9–10: deformation and rate along it).
    geometry: ContactGeometry,
    onset: OnsetDetector,
    contact: Option<(f64, Vector3<f64>)>,
    window: WindowEstimator,
    next_sample: f64,
    refits: Option<RefitSchedule>,
    /// The named effects carried in every refit (a model the discrepancy workflow augmented): its kind,
    /// exponents and effects' shapes are kept, their amplitudes refitted ([`fit_with_effects`]); and
    /// where it places the surface in the world, if the window is not to move it.
    structure: Option<(ContactModel, Option<Vector3<f64>>)>,
}

/// The farthest a surface point may lie from the arm's base \[m\] (the LWR reaches 1.2 m).
pub const MAX_SURFACE_DISTANCE: f64 = 5.0;

/// When the node refits on its own: every `period` \[s\] of reading time, once the window is at least
/// `min_window_fill` full (`Params::refit_period`, `min_window_fill`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefitSchedule {
    pub period: f64,
    pub min_window_fill: f64,
    /// The reading time from which the next refit is due \[s\].
    pub next: f64,
}

impl ContactEstimatorNode {
    pub fn new(config: EstimatorConfig) -> Result<Self, ContactError> {
        let geometry = ContactGeometry::lwr4(config.normal)
            .ok_or_else(|| ContactError::InvalidConfig("the contact normal must not be zero".into()))?;
        if !(config.sample_period.is_finite() && config.sample_period > 0.0) {
            return Err(ContactError::InvalidConfig("sample period must be positive".into()));
        }
        Ok(Self {
            onset: OnsetDetector::new(config.onset)?,
            window: WindowEstimator::new(config.window, config.fit)?,
            contact: None,
            next_sample: 0.0,
            refits: None,
            structure: None,
            geometry,
            config,
        })
    }

    /// Refits on the schedule of `p` from reading time `from` on (the graph's node and the demo's cell
    /// alike); without it the node refits only when asked ([`Self::refit`]).
    pub fn with_refits(mut self, p: &Params, from: f64) -> Self {
        self.refits =
            Some(RefitSchedule { period: p.refit_period, min_window_fill: p.min_window_fill.max(1e-9), next: from });
        self
    }

    /// Carries the effects of `structure` (a model with named effects) in every refit. With `surface`
    /// (a point of the undeformed surface in the world) the refits hold the surface there: a window that
    /// never leaves the surface cannot tell its place from a sensor offset, and the workflow placed it
    /// with free space in view. A model without effects is the plain estimator's choice of kind.
    pub fn with_effects(
        mut self,
        structure: ContactModel,
        surface: Option<Vector3<f64>>,
    ) -> Result<Self, ContactError> {
        structure.plausible()?;
        if surface.is_some_and(|p| !(p.iter().all(|v| v.is_finite()) && p.norm() <= MAX_SURFACE_DISTANCE)) {
            return Err(ContactError::InvalidConfig(format!(
                "the surface point must be finite and within {MAX_SURFACE_DISTANCE} m of the arm's base"
            )));
        }
        // The window holds a sample every sample_period: a faster branch is not in it to refit.
        let fastest = 2.0 * self.config.sample_period;
        for e in &structure.effects {
            if let softcontact_contact::Effect::ViscoelasticRelaxation { time_constant, .. } = *e
                && time_constant < fastest
            {
                return Err(ContactError::InvalidConfig(format!(
                    "a relaxation time constant of {time_constant} s: the window, sampled every {} s, cannot refit a branch faster than {fastest} s",
                    self.config.sample_period
                )));
            }
        }
        self.structure = (!structure.effects.is_empty()).then_some((structure, surface));
        Ok(self)
    }

    /// The refit due at reading time `t` on the schedule, if one is: the model, or why it failed.
    pub fn refit_if_due(&mut self, t: f64) -> Option<Result<ModelOut, ContactError>> {
        let fill = self.window_fill();
        let schedule = self.refits.as_mut()?;
        if !(t >= schedule.next && fill >= schedule.min_window_fill) {
            return None;
        }
        schedule.next = t + schedule.period;
        Some(self.refit())
    }

    /// One reading at time t \[s\]: tool position and velocity in the world, normal force f = −F·n.
    pub fn update(
        &mut self,
        t: f64,
        position: &Vector3<f64>,
        velocity: &Vector3<f64>,
        normal_force: f64,
    ) -> Result<ContactStateOut, ContactError> {
        let along = self.geometry.along(position);
        if let Some(event) = self.onset.update(along, normal_force)? {
            match event {
                OnsetEvent::Contact { position: level } if self.contact.is_none() => {
                    self.contact = Some((level, position - (along - level) * self.geometry.normal()));
                }
                _ => {}
            }
        }
        let Some((level, _)) = self.contact else {
            return Ok(ContactStateOut { normal_force, ..Default::default() });
        };
        let out = ContactStateOut {
            deformation: along - level,
            deformation_rate: self.geometry.rate(velocity),
            normal_force,
            in_contact: self.onset.in_contact(),
        };
        // In-contact samples only: where the surface has let go, the law says nothing.
        if t >= self.next_sample {
            self.next_sample = t + self.config.sample_period;
            if out.in_contact && normal_force > self.config.onset.threshold {
                self.window.push_at(t, Sample::new(out.deformation, out.deformation_rate, normal_force)?)?;
            }
        }
        Ok(out)
    }

    /// Samples in the window.
    pub fn samples(&self) -> usize {
        self.window.len()
    }

    /// The window's samples, oldest first (deformation from the onset position).
    pub fn window_samples(&self) -> impl Iterator<Item = &Sample> {
        self.window.samples()
    }

    /// The fraction of the window filled.
    pub fn window_fill(&self) -> f64 {
        self.window.len() as f64 / self.window.capacity() as f64
    }

    /// Refits every kind over the window, chooses one, and places the surface.
    pub fn refit(&mut self) -> Result<ModelOut, ContactError> {
        let (_, onset_point) = self.contact.ok_or(ContactError::NotEnoughData { kind: "a contact" })?;
        let estimate = self.window.refit()?;
        let chosen = estimate.selected_fit().clone();
        let samples: Vec<Sample> = self.window.samples().copied().collect();
        let prior = Some((chosen.stiffness, chosen.damping));
        let (offset, model) = match &self.structure {
            Some((structure, surface)) => {
                let timed: Vec<TimedSample> = self.window.timed_samples().collect();
                let fitted = match surface {
                    Some(p) => {
                        let offset = self.geometry.deformation(p, &onset_point);
                        (offset, fit_with_effects_at(&timed, structure, offset)?)
                    }
                    None => fit_with_effects(&timed, structure, self.config.offset_range)?,
                };
                // A window that cannot tell the effects apart may fit wild amplitudes: such a model is
                // not published (the controller would refuse it too).
                fitted.1.plausible()?;
                fitted
            }
            None => {
                let (offset, fit) = estimate_contact_offset(
                    &samples,
                    chosen.exponents,
                    self.config.offset_range,
                    prior,
                    &self.config.fit,
                )?;
                (offset, fit.model()?)
            }
        };
        Ok(ModelOut {
            model,
            offset,
            contact_position: onset_point + offset * self.geometry.normal(),
            window_fill: self.window_fill(),
            stiffness_excited: !chosen.stiffness_held,
            damping_excited: !chosen.damping_held,
            estimate,
        })
    }
}

/// /contact_estimator/model as the message the nodes exchange.
pub type ModelMsg = softcontact_msgs::softcontact_msgs::ContactModel;

impl ModelOut {
    pub fn to_msg(&self, header: softcontact_msgs::std_msgs::Header) -> ModelMsg {
        let m = &self.model;
        let p = self.contact_position;
        ModelMsg {
            header,
            kind: m.kind.id().into(),
            stiffness: m.stiffness,
            damping: m.damping,
            exponent_a: m.exponents.a,
            exponent_b: m.exponents.b,
            exponent_c: m.exponents.c,
            contact_position: softcontact_msgs::geometry_msgs::Point { x: p.x, y: p.y, z: p.z },
            candidate_kinds: self.estimate.fits.iter().map(|f| f.kind.id().into()).collect(),
            candidate_fitness_mean: self.estimate.fits.iter().map(|f| f.fitness_mean).collect(),
            candidate_fitness_std: self.estimate.fits.iter().map(|f| f.fitness_std).collect(),
            window_fill: self.window_fill,
            stiffness_excited: self.stiffness_excited,
            damping_excited: self.damping_excited,
            effects: m
                .effects
                .iter()
                .map(|e| softcontact_msgs::softcontact_msgs::ContactEffect {
                    id: e.id().into(),
                    parameters: e.parameter_list(),
                })
                .collect(),
        }
    }
}

/// The contact model and the surface position a /contact_estimator/model message carries, checked
/// (a model from the wire is refused rather than trusted if it is not physical).
pub fn model_from_msg(msg: &ModelMsg) -> Result<(ContactModel, Vector3<f64>), ContactError> {
    let kind: softcontact_contact::Kind =
        serde_json::from_value(serde_json::Value::String(msg.kind.clone())).map_err(|_| {
            ContactError::InvalidConfig(format!(
                "unknown model kind `{}`",
                msg.kind.chars().take(40).collect::<String>()
            ))
        })?;
    let exponents = softcontact_contact::Exponents { a: msg.exponent_a, b: msg.exponent_b, c: msg.exponent_c };
    let mut model = ContactModel::general(msg.stiffness, msg.damping, exponents)?;
    if kind.exponents().is_some_and(|e| e == exponents) {
        model = ContactModel::new(kind, msg.stiffness, msg.damping)?;
    }
    if msg.effects.len() > softcontact_contact::MAX_EFFECTS {
        return Err(ContactError::InvalidModel(format!(
            "{} effects (at most {})",
            msg.effects.len(),
            softcontact_contact::MAX_EFFECTS
        )));
    }
    model.effects =
        msg.effects.iter().map(|e| Effect::from_parameters(&e.id, &e.parameters)).collect::<Result<_, _>>()?;
    model.validate()?;
    let p = &msg.contact_position;
    let position = Vector3::new(p.x, p.y, p.z);
    if !position.iter().all(|v| v.is_finite()) {
        return Err(ContactError::InvalidConfig("contact position is not finite".into()));
    }
    Ok((model, position))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand pressing a Kelvin-Voigt surface (k 2000 N/m) at 1 Hz, read at 1 kHz.
    fn reading(t: f64) -> (Vector3<f64>, Vector3<f64>, f64) {
        let z = 0.004 + 0.002 * (std::f64::consts::TAU * t).sin();
        let zdot = 0.002 * std::f64::consts::TAU * (std::f64::consts::TAU * t).cos();
        let n = Vector3::new(0.0, 0.0, -1.0);
        (n * (0.3 + z), n * zdot, 2000.0 * z + 5.0 * zdot)
    }

    /// A Kelvin-Voigt surface (k 2000 N/m, λ 5 N s/m, under z = 0 at 0.3 m) with a Maxwell branch
    /// (1000 N/m, τ 0.5 s), read with a sensor offset of 0.3 N: the node fed `seconds` of a press at
    /// 1 Hz and 0.1 Hz (the slow one lets the branch relax, which tells it from the spring).
    fn fed_augmented(node: &mut ContactEstimatorNode, seconds: f64) {
        use std::f64::consts::TAU;
        let (km, tau) = (1000.0, 0.5_f64);
        let n = Vector3::new(0.0, 0.0, -1.0);
        let mut branch = 0.0;
        let mut z_prev = None;
        for i in 0..(seconds * 1e3) as usize {
            let t = i as f64 * 1e-3;
            let z = 0.006 + 0.002 * (TAU * t).sin() + 0.003 * (TAU * 0.1 * t).sin();
            let zdot = 0.002 * TAU * (TAU * t).cos() + 0.003 * TAU * 0.1 * (TAU * 0.1 * t).cos();
            if let Some(prev) = z_prev {
                // Exact for a deformation changing at a constant rate over the step.
                let decay = (-1e-3 / tau).exp();
                branch = branch * decay + km * tau * (z - prev) / 1e-3 * (1.0 - decay);
            }
            z_prev = Some(z);
            let f = 2000.0 * z + 5.0 * zdot + branch;
            node.update(t, &(n * (0.3 + z)), &(n * zdot), f + 0.3).unwrap();
        }
    }

    fn structure() -> ContactModel {
        ContactModel {
            effects: vec![
                Effect::ViscoelasticRelaxation { stiffness: 500.0, time_constant: 0.5 },
                Effect::SensorBias { offset: 0.0 },
            ],
            ..ContactModel::new(softcontact_contact::Kind::KelvinVoigt, 1000.0, 0.0).unwrap()
        }
    }

    #[test]
    fn the_parameters_augmented_model_is_carried_in_every_refit_and_on_the_wire() {
        let surface = [0.0, 0.0, -0.3];
        let p = Params {
            window: 1200,
            augmented_model: Some(structure()),
            surface_position: Some(surface),
            ..Params::default()
        };
        let mut node = p.estimator(0.0).unwrap();
        fed_augmented(&mut node, 12.0);
        let out = node.refit().unwrap();
        // The branch and the offset of the hidden truth, refitted with the time constant kept.
        let ids: Vec<&str> = out.model.effects.iter().map(Effect::id).collect();
        assert_eq!(ids, ["viscoelastic_relaxation", "sensor_bias"]);
        match out.model.effects[0] {
            Effect::ViscoelasticRelaxation { stiffness, time_constant } => {
                assert!((stiffness - 1000.0).abs() < 20.0, "branch {stiffness} N/m for 1000");
                assert_eq!(time_constant, 0.5);
            }
            other => panic!("{other:?}"),
        }
        match out.model.effects[1] {
            Effect::SensorBias { offset } => assert!((offset - 0.3).abs() < 0.05, "offset {offset} N for 0.3"),
            other => panic!("{other:?}"),
        }
        assert!((out.contact_position - Vector3::from(surface)).norm() < 1e-9, "{}", out.contact_position);
        // The message carries every effect: what the controller reads is what the estimator fitted.
        let header = softcontact_msgs::std_msgs::Header::default();
        let (model, position) = model_from_msg(&out.to_msg(header)).unwrap();
        assert_eq!(model, out.model);
        assert_eq!(position, out.contact_position);
        // A refit beyond what is plausible is not published: here a reading 30 N off (a bias beyond 20 N).
        let mut off = p.estimator(0.0).unwrap();
        for i in 0..12_000 {
            let t = i as f64 * 1e-3;
            let (position, velocity, f) = reading(t);
            off.update(t, &position, &velocity, f + 30.0).unwrap();
        }
        let refused = off.refit().unwrap_err().to_string();
        assert!(refused.contains("implausible") && refused.contains("sensor bias"), "{refused}");
        // Without the parameter, the plain estimator.
        let mut plain = Params { window: 1200, ..Params::default() }.estimator(0.0).unwrap();
        fed_augmented(&mut plain, 12.0);
        assert!(plain.refit().unwrap().model.effects.is_empty());
    }

    #[test]
    fn augmented_parameters_and_effects_from_the_wire_are_checked() {
        use crate::runtime::params::NodeParams;
        let bad = |p: Params| p.validate().unwrap_err();
        let lone = bad(Params { surface_position: Some([0.0, 0.0, 0.3]), ..Params::default() });
        assert!(lone.contains("there is none"), "{lone}");
        let nan = bad(Params {
            augmented_model: Some(structure()),
            surface_position: Some([0.0, f64::NAN, 0.3]),
            ..Params::default()
        });
        assert!(nan.contains("not finite"), "{nan}");
        let mut loud = structure();
        loud.effects.push(Effect::SensorDrift { rate: 5.0 });
        assert!(bad(Params { augmented_model: Some(loud), ..Params::default() }).contains("implausible"));

        let far = bad(Params {
            augmented_model: Some(structure()),
            surface_position: Some([1e300, 0.0, 0.3]),
            ..Params::default()
        });
        assert!(far.contains("farther than"), "{far}");
        // A branch faster than the window's samples cannot be refitted from it.
        let mut fast = structure();
        fast.effects[0] = Effect::ViscoelasticRelaxation { stiffness: 500.0, time_constant: 0.005 };
        let quick = bad(Params { augmented_model: Some(fast), ..Params::default() });
        assert!(quick.contains("cannot refit a branch faster than 0.02 s"), "{quick}");

        let effect = |id: &str, parameters: Vec<f64>| softcontact_msgs::softcontact_msgs::ContactEffect {
            id: id.into(),
            parameters,
        };
        let msg = |effects| ModelMsg {
            kind: "kelvin_voigt".into(),
            stiffness: 1000.0,
            exponent_a: 1.0,
            exponent_c: 1.0,
            effects,
            ..ModelMsg::default()
        };
        assert_eq!(model_from_msg(&msg(vec![effect("sensor_bias", vec![0.2])])).unwrap().0.effects.len(), 1);
        for (effects, words) in [
            (vec![effect("gremlins", vec![1.0])], "unknown effect"),
            (vec![effect("sensor_bias", vec![f64::NAN])], "finite"),
            (vec![effect("sensor_bias", vec![1e300, 2.0])], "takes 1 parameters"),
            (vec![effect("viscoelastic_relaxation", vec![-1.0, 0.5])], "stiffness must be ≥ 0"),
            (vec![effect("hysteresis", vec![f64::INFINITY, 0.1])], "finite"),
            (vec![effect("sensor_bias", vec![0.1]); 9], "9 effects"),
        ] {
            let err = model_from_msg(&msg(effects)).unwrap_err().to_string();
            assert!(err.contains(words), "expected `{words}` in `{err}`");
        }
    }

    #[test]
    fn refits_come_on_the_schedule_once_the_window_is_full_enough() {
        let p = Params { window: 200, refit_period: 0.5, min_window_fill: 0.5, ..Params::default() };
        let mut node = ContactEstimatorNode::new(p.estimator_config()).unwrap().with_refits(&p, 0.0);
        let mut due = Vec::new();
        for i in 0..4000 {
            let t = i as f64 * 1e-3;
            let (position, velocity, f) = reading(t);
            node.update(t, &position, &velocity, f).unwrap();
            if let Some(model) = node.refit_if_due(t) {
                assert!(node.window_fill() >= 0.5, "refit at fill {}", node.window_fill());
                due.push((t, model.is_ok()));
            }
        }
        // 100 samples (10 ms apart) fill half the window: the first refit after 1 s of contact, then every 0.5 s.
        assert!(due.len() >= 5, "{due:?}");
        assert!((due[0].0 - 1.0).abs() < 0.05, "first refit at {} s", due[0].0);
        for w in due.windows(2) {
            assert!((w[1].0 - w[0].0 - 0.5).abs() < 1.5e-3, "refits {} s apart", w[1].0 - w[0].0);
        }
        assert!(due.iter().all(|(_, ok)| *ok), "{due:?}");
        // Without a schedule the node refits only when asked.
        let mut quiet = ContactEstimatorNode::new(p.estimator_config()).unwrap();
        assert!(quiet.refit_if_due(10.0).is_none());
    }
}
