//! The `contact_estimator` node's parameters, each declared once.

use nalgebra::Vector3;
use softcontact_contact::{ContactError, ContactModel, FitConfig, OnsetConfig};

use super::{ContactEstimatorNode, EstimatorConfig, MAX_SURFACE_DISTANCE};

/// The `contact_estimator` node's parameters (config/contact_estimator.yaml). What each means and the values it takes are
/// declared once, in `declare` (`NodeParams`), which checks them at start-up and describes them over ROS.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    pub normal: [f64; 3],
    pub sample_period: f64,
    pub window: usize,
    pub onset_threshold: f64,
    pub onset_confirm: usize,
    pub folds: usize,
    pub max_relative_error: f64,
    pub offset_range: [f64; 2],
    pub refit_period: f64,
    pub min_window_fill: f64,
    pub state_rate: f64,
    pub stale_after: f64,
    pub dead_after: f64,
    /// The model `softcontact discrepancy --out` augmented with named effects, carried in every refit.
    pub augmented_model: Option<ContactModel>,
    /// Where that workflow placed the undeformed surface in the world: the refits hold it there.
    pub surface_position: Option<[f64; 3]>,
    pub use_sim_time: bool,
}

impl Default for Params {
    fn default() -> Self {
        let c = EstimatorConfig::default();
        Self {
            normal: c.normal.into(),
            sample_period: c.sample_period,
            window: c.window,
            onset_threshold: c.onset.threshold,
            onset_confirm: c.onset.confirm,
            folds: c.fit.folds,
            max_relative_error: c.fit.max_relative_error,
            offset_range: [c.offset_range.0, c.offset_range.1],
            refit_period: 1.0,
            min_window_fill: 0.25,
            state_rate: 100.0,
            stale_after: 0.05,
            dead_after: 2.0,
            augmented_model: None,
            surface_position: None,
            use_sim_time: false,
        }
    }
}

impl Params {
    pub fn estimator_config(&self) -> EstimatorConfig {
        EstimatorConfig {
            normal: self.normal.into(),
            sample_period: self.sample_period,
            window: self.window,
            onset: OnsetConfig { threshold: self.onset_threshold, confirm: self.onset_confirm },
            fit: FitConfig { folds: self.folds, max_relative_error: self.max_relative_error, ..Default::default() },
            offset_range: (self.offset_range[0], self.offset_range[1]),
        }
    }

    /// The node these parameters describe: refitting on their schedule from reading time `from` on, with
    /// the effects of `augmented_model` held at `surface_position` if they are given.
    pub fn estimator(&self, from: f64) -> Result<ContactEstimatorNode, ContactError> {
        let node = ContactEstimatorNode::new(self.estimator_config())?.with_refits(self, from);
        match &self.augmented_model {
            Some(model) => node.with_effects(model.clone(), self.surface_position.map(Vector3::from)),
            None => Ok(node),
        }
    }
}

impl crate::runtime::params::NodeParams for Params {
    fn declare(&self, d: &mut crate::runtime::params::Declarations) {
        d.direction("normal", self.normal, "contact direction n in the world");
        d.above(
            "sample_period",
            self.sample_period,
            (0.0, 1.0),
            "time between window samples (the force-control paper: 10 ms) [s]",
        );
        d.integer(
            "window",
            self.window as i64,
            (10 * self.folds.max(1) as i64, 1_000_000),
            "samples in the window (the force-control paper: 1200; at least 10 per fold)",
        );
        d.onset(self.onset_threshold, self.onset_confirm);
        d.integer("folds", self.folds as i64, (1, 100), "cross-validation folds of the model selection");
        d.above(
            "max_relative_error",
            self.max_relative_error,
            (0.0, 100.0),
            "excitation guard: largest relative standard error of an identified parameter",
        );
        let [lo, hi] = self.offset_range;
        let ordered = if lo.is_finite() && hi.is_finite() && lo < hi {
            Ok(())
        } else {
            Err(format!("{:?} is not [low, high]", self.offset_range))
        };
        d.rule(
            "offset_range",
            ordered,
            "[low, high], low < high [m]",
            "where to search for the undeformed surface relative to the onset position, along n [m]",
        );
        d.above(
            "refit_period",
            self.refit_period,
            (0.0, 3600.0),
            "time between refits, each published on /contact_estimator/model [s]",
        );
        d.within(
            "min_window_fill",
            self.min_window_fill,
            (0.0, 1.0),
            "no model is published before the window is this full",
        );
        d.above("state_rate", self.state_rate, (0.0, 1000.0), "/contact_estimator/state rate [Hz]");
        d.above(
            "stale_after",
            self.stale_after,
            (0.0, 10.0),
            "a force reading with no pose within this of its stamp is not paired (stamps of one clock: the driver's and the sensor node's) [s]",
        );
        crate::runtime::liveness::declare_dead_after(
            d,
            self.dead_after,
            0.0,
            "/ft_sensor/wrench or /lwr/ee_pose silent this long after they flowed (both are due at 1 kHz): their publisher or the middleware is dead, and the node exits with an error [s]",
        );
        d.rule(
            "augmented_model",
            self.augmented_model.as_ref().map_or(Ok(()), |m| m.plausible().map_err(|e| e.to_string())),
            "null, or a plausible contact model with named effects",
            "the model the discrepancy workflow augmented (`softcontact discrepancy FILE --out DIR` writes it into DIR/NAME.params.yaml): every refit keeps its kind, exponents and effects' time constants and refits their amplitudes",
        );
        let surface = match (self.surface_position, &self.augmented_model) {
            (Some(p), _) if !(p.iter().all(|v| v.is_finite()) && Vector3::from(p).norm() <= MAX_SURFACE_DISTANCE) => {
                Err(format!("{p:?} is not finite or farther than {MAX_SURFACE_DISTANCE} m from the base"))
            }
            (Some(_), None) => Err("it places the surface of an augmented_model, and there is none".into()),
            _ => Ok(()),
        };
        d.rule(
            "surface_position",
            surface,
            "null, or a point [x, y, z] within 5 m of the base [m], with augmented_model",
            "where the discrepancy workflow placed the undeformed surface in the world: the refits of augmented_model hold it there (a window that never leaves the surface cannot tell its place from a sensor offset) [m]",
        );
        d.use_sim_time();
        // The estimator checks its configuration as it is built.
        d.together(self.estimator(0.0).map(|_| ()).map_err(|e| e.to_string()));
    }
}
