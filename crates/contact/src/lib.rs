//! Contact models of soft surfaces and their estimation from noisy data. Pure library code: no I/O,
//! no clocks; the estimator node, the controller, the simulator and the offline tools all use it.
//!
//! # Models
//!
//! [`ContactModel`] is the one description of a contact, read from and written to YAML:
//! - normal force f = k zᵃ + λ zᵇ żᶜ for z > 0, 0 otherwise (the force-control paper's eq. 2), never negative, with
//!   named [`Kind`]s Kelvin-Voigt (a = c = 1, b = 0), Hunt-Crossley (a = b = 3/2, c = 1),
//!   Azad-Featherstone (a = 3/2, b = 1/2, c = 1), Hertz-Walton's normal part, or general exponents;
//!   żᶜ keeps the sign of ż (sgn(ż)|ż|ᶜ);
//! - optionally a tangential law ([`Tangential`]): the snake paper's Walton law f_t = k_t √z δ_t, or the
//!   incremental Mindlin–Deresiewicz law that agrees with it on straight paths and carries the path's
//!   history off them, both inside the friction cone;
//! - optionally named [`Effect`]s (viscoelastic relaxation, hysteresis, contact-offset drift, sensor
//!   bias and drift) with their own state, advanced by [`ContactModel::step`].
//!
//! Each model gives the force, ∂f/∂z and ∂f/∂ż, and the inverse the controller uses: the deformation
//! that holds a force at rest, z = (f/k)^{1/a} (the force-control paper's eq. 19).
//!
//! # Sign conventions (docs/conventions.md)
//!
//! n is the unit vector along which the hand moves to compress the surface (default [0, 0, −1] in
//! `world`); d is where the tool was when contact began. Deformation z = (r − d)·n, rate ż = ṙ·n, normal
//! force f = −F·n ≥ 0 with F the force the surface exerts on the hand. So z > 0 and f > 0 in contact, and
//! ż > 0 while pressing in.
//!
//! # Which estimator when
//!
//! - Online, every sample: [`WindowEstimator`] keeps the last N samples (default 1200, 12 s at 10 ms)
//!   with running least-squares moments of every candidate kind, O(1) per sample;
//!   [`WindowEstimator::current`] reads the current (k, λ) of a kind at once.
//! - Online, when a model is adopted (e.g. once per command cycle, as in the force-control paper):
//!   [`WindowEstimator::refit`] refits every kind with 5-fold cross-validated fitness (the force-control paper's eq. 18),
//!   chooses the best, and applies the excitation guard: a parameter the window does not determine
//!   (λ during a long hold, where ż ≈ 0) stays at its prior and is flagged, instead of following noise.
//! - Offline, a whole recording: [`estimate`] on all samples; [`estimate_contact_offset`] when the
//!   onset threshold misplaces the surface (it always does on a soft sponge: 1 N is reached only after
//!   some deformation); [`estimate_exponent`] when none of the named laws fits; [`robust_least_squares`]
//!   when the data has outliers (Huber-weighted, QR-solved).
//! - Feed estimators in-contact samples only: where the hand withdraws faster than the surface recovers,
//!   the surface separates and the force is 0 rather than the law's negative value, so such samples
//!   (f below the onset threshold) say nothing about the law and bias it.
//! - Contact onset: [`OnsetDetector`] (threshold 1 N, confirmed by 3 consecutive readings).
//! - Reporting as the snake paper does: [`fit_statistics`] and [`dispersion`]; its 205 loading paths and what a
//!   model predicts at their ends: [`seed_000_experiments`], [`predicted_dispersion`].

mod effect_fit;
mod effect_laws;
mod exponent;
mod fit;
mod limits;
mod loading_paths;
mod model;
mod onset;
mod stats;
mod tangential;
mod tangential_fit;
mod window;

pub use effect_fit::{MIN_EFFECT_SAMPLES, TimedSample, fit_with_effects, fit_with_effects_at};
pub use exponent::{DampingExponent, estimate_contact_offset, estimate_exponent, minimize_scalar};
pub use fit::{
    Fit, FitConfig, Moments, Prior, Sample, fit, fit_folds, fitness, fold_moments, fold_of, least_squares_qr,
    regressors, robust_least_squares,
};
pub use loading_paths::{
    CONVERGENCE_ANGLE, FINAL_NORMAL_FORCE, Family, LoadingPath, N_PER_MM_1_5, SET_ANGLES, convergence_points,
    corner_path, fit_normal_stiffness, fit_normal_stiffness_and_zero, fit_tangential_stiffness, forces_at_end,
    predicted_dispersion, seed_000_experiments,
};
pub use model::{
    ContactModel, DELAY_LINE, Effect, EffectState, Exponents, Kind, MAX_ADHESION, MAX_ADHESION_RANGE,
    MAX_CONTACT_STIFFNESS, MAX_DELAY, MAX_EFFECTS, MAX_HYSTERESIS, MAX_MEDIUM_DRAG, MAX_SENSOR_BIAS, MAX_SENSOR_DRIFT,
    MAX_SQUEEZE_REACH, MAX_SURFACE_DRIFT, MAX_TARE_SPEED, MIN_HYSTERESIS_SCALE, PLAUSIBLE_DEPTH, PLAUSIBLE_EXPONENTS,
    SensorInputs, TIME_CONSTANT_RANGE, adhesion_share, finite, gap_of, gravity_change, maxwell_step,
    maxwell_step_with_decay, next_adhesion_peak,
};
pub use onset::{OnsetConfig, OnsetDetector, OnsetEvent};
pub use stats::{Dispersion, FitStatistics, dispersion, fit_statistics};
pub use tangential::{MindlinDeresiewicz, Tangential, TangentialLaw, TangentialMemory};
pub use tangential_fit::{
    PathSample, TangentialFit, TangentialIdentification, identify_tangential, thinned, with_hertz,
};
pub use window::{Estimate, WindowEstimator, estimate};

/// Why a contact computation was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ContactError {
    #[error("{name} is not a finite number ({value})")]
    NonFinite { name: &'static str, value: f64 },
    #[error("a contact force cannot be negative (got {0} N)")]
    NegativeForce(f64),
    #[error("invalid contact model: {0}")]
    InvalidModel(String),
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    #[error("not enough informative samples to fit {kind}")]
    NotEnoughData { kind: &'static str },
}
