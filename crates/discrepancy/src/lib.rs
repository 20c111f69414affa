//! The discrepancy workflow (design section 7): find what a contact model misses in a recording, name it
//! from a library of physical effects, or say that nothing is missing, or that it is not in the library.
//!
//! Pure: a [`Series`] and a baseline [`ContactModel`] in, a [`Report`] (serialisable to the `softcontact
//! discrepancy` JSON) and the augmented [`ContactModel`] out. No files, clocks or threads.
//!
//! # Method (see also this crate's README.md)
//! 1. **Phases** ([`phases`]): `free`, `approach`, `loading`, `holding`, `unloading` from z and ż with a
//!    velocity threshold taken from the data ([`velocity_threshold`]).
//! 2. **Noise floor** ([`noise_floor`]): σ of the force in free space after removing a mean and a linear
//!    trend, else from first differences in holds (σ ≈ std(Δf)/√2).
//! 3. **Re-simulate** the baseline with [`ContactModel::step`] (the simulator's own code); residual =
//!    measured − predicted; every RMS is over the in-contact samples (z > 0), also per phase.
//! 4. **Anything to explain?** The baseline's k and λ are refitted (exponents fixed); if the in-contact RMS
//!    is within [`Options::floor_margin`] of σ and the residual is nearly white, the answer is
//!    [`Remaining::None`] with no effect named. Refusing is a first-class answer.
//! 5. **Name**: each candidate is a physical augmentation with SI parameters (ids `sensor_bias`,
//!    `sensor_drift`, `viscoelastic_relaxation`, `hysteresis`, `stiffness_exponent`,
//!    `contact_offset_drift`, and the others of the crate's README; `quasi_linear_relaxation` and
//!    `medium_drag` are tried once the rounds are done). For a shape parameter on a grid (τ, v₀, a′) the model is linear in its
//!    amplitudes; each candidate is fitted **jointly** with k and λ (and the effects already accepted) on
//!    columns scaled to unit RMS. A candidate (or a pair of candidates, so that two hidden effects do not
//!    mask each other) is accepted only if, against the current model:
//!    - its held-out MSE over [`Options::folds`] interleaved folds (each holding a part of both halves
//!      of the contact and of the free space around it: `folds::interleaved_folds`) improves by at least
//!      [`Options::min_gain`] (relative), and its AICc by at least [`Options::min_delta_aicc`];
//!    - it explains at least [`Options::min_share`] of the current excess held-out MSE over σ² (a
//!      candidate explaining a sliver of a large structured residual is a proxy, not a discovery);
//!    - it does not fit free space worse (there the force is the sensor's alone);
//!    - every new amplitude has |t| ≥ [`Options::min_t`] with its variance inflated by (1+ρ)/(1−ρ) for the
//!      lag-1 autocorrelation ρ of the candidate model's residual (a proxy that leaves structure behind
//!      gets a large ρ and so a small t), **and** the same sign in every fold's fit;
//!    - its parameters are physical (k_m > 0, 0 < h < 1, k > 0);
//!    - no rival of another id has fitted contributions correlated beyond [`Options::collinear_corr`]
//!      with a held-out MSE within [`Options::rival_ratio`]× and a gain at least 1/[`Options::rival_ratio`]
//!      of the best one's, both over folds contiguous in time (`folds::contiguous_folds`: alike over the
//!      record, two effects differ by how they extrapolate): then the pair is reported `ambiguous` with the
//!      excitation that would separate it, and nothing is named from it.
//! 6. **Iterate**: add the accepted effect (the best single one; a pair only when no single passes), refit
//!    everything with the surface position, drop an earlier effect the new one made redundant, repeat (at
//!    most [`Options::max_rounds`]); then polish every shape (τ, v₀) in the final structure.
//!    The end is `none` (at the noise floor), `unexplained` (structured residual no candidate explains —
//!    an effect outside the library ends here) or `ambiguous`.
//! 7. **Add**: the augmented [`ContactModel`] (same type; `stiffness_exponent` makes the kind `general`)
//!    is re-simulated with [`ContactModel::step`] for the RMS after, overall and per phase.
//! 8. **A wrong kind fixed, not patched** (`law.rs`): where another kind of the force-control paper's three,
//!    refitted, predicts held-out data better than the given law by [`Options::min_gain`], steps 4–7 run
//!    on it too, and it replaces the given kind if its final model fits the record better by that margin
//!    ([`Report::law_rechosen`]).
//!
//! The lessons behind these choices (columns made dimensionless, joint fits, two fold layouts, AICc, margins,
//! collinearity, refusing out-of-library effects) are summarised in the crate's README.md (crates/discrepancy).
//!
//! # Files, in the order the workflow uses them
//! `series.rs` (the samples, checked) → `phase.rs` (phases, noise floor) → `scales.rs` (the record's
//! scales: shape grids, floors, bounds) → `term.rs` (the augmentation terms) → `fit.rs` (the linear columns and the joint fit, held-out by
//! folds) → `family.rs` (the library as screened: id, term, grid) → `candidate.rs` (one candidate fitted
//! and judged, the rules it must pass) → `refine.rs` (the named shapes refined together) →
//! `augmented.rs` (the augmented model, its simulated gap, the surface, parameters and intervals) →
//! `report.rs` (what is reported, where the gap is) → `analysis.rs` (the steps [`analyse`] runs, one
//! method each: refit the baseline, the rounds of naming and adding, the checks after them) → `law.rs`
//! (the other kinds, refitted, as rivals of the given one). Beside them:
//! `drag.rs` (what a medium's drag is read against), `wrench.rs` (every wrench channel), `arm.rs` (the arm's own effects), `loading_paths.rs` (tangential
//! path effects).

mod analysis;
mod arm;
mod augmented;
mod candidate;
mod drag;
mod family;
mod fit;
mod folds;
mod golden;
mod lateral;
mod law;
mod loading_paths;
mod phase;
mod refine;
mod report;
mod scales;
mod series;
mod term;
#[cfg(test)]
mod tests;
mod wrench;

use std::collections::BTreeMap;

use serde::Serialize;
use softcontact_contact::{ContactError, ContactModel, Effect, Exponents, Kind, MAX_DELAY, SensorInputs};

pub use arm::{ArmEffect, ArmError, ArmOptions, ArmReport, ArmSample, name_arm_effects};
use fit::{Data, Fit, Structure, Term};
pub use loading_paths::{PathEffect, PathNamed, PathOptions, PathReport, name_path_effects};
pub use wrench::{CHANNELS, Channel, Wrench, predict_wrench};

use analysis::Analysis;
use augmented::*;
use candidate::*;
use family::*;
pub use phase::*;
use refine::*;
pub use report::*;
pub use scales::*;
pub use series::*;

/// Why [`analyse`] refused its input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiscrepancyError {
    #[error("the series' columns differ in length (t {t}, z {z}, zdot {zdot}, f {f})")]
    Lengths { t: usize, z: usize, zdot: usize, f: usize },
    #[error("`{name}` has {len} samples, the series {n}")]
    InputLength { name: &'static str, len: usize, n: usize },
    #[error("`{name}` is not finite at sample {index}")]
    NonFinite { name: &'static str, index: usize },
    #[error("time stamps must increase strictly (sample {0})")]
    Time(usize),
    #[error("`{name}` must be a unit vector (its norm is {norm})")]
    NotUnit { name: &'static str, norm: f64 },
    #[error(
        "too few samples: {got} ({in_contact} in contact); need {MIN_SAMPLES} and {MIN_CONTACT_SAMPLES} in contact"
    )]
    TooShort { got: usize, in_contact: usize },
    /// (Not a source as well: the message holds it, and `{:#}` would print it twice.)
    #[error("baseline model: {0}")]
    Model(ContactError),
}

impl From<ContactError> for DiscrepancyError {
    fn from(e: ContactError) -> Self {
        DiscrepancyError::Model(e)
    }
}

/// The measured force `model` predicts at every sample, stepped with [`ContactModel::step`] from a fresh
/// state.
pub fn simulate(model: &ContactModel, series: &Series) -> Result<Vec<f64>, DiscrepancyError> {
    Ok(steps(model, series)?.into_iter().map(|(_, measured)| measured).collect())
}

/// (surface force, measured force) at every sample, stepped with [`ContactModel::step`] from a fresh state,
/// the sensor tared where the series says.
pub(crate) fn steps(model: &ContactModel, series: &Series) -> Result<Vec<(f64, f64)>, DiscrepancyError> {
    let mut state = model.effect_state();
    let dt = step_sizes(series);
    let tared = series.tared_before();
    (0..series.len())
        .map(|i| {
            if tared[i] {
                state.tare();
            }
            let surface = model.step_surface(&mut state, series.z[i], series.zdot[i], dt[i])?;
            Ok((surface, model.sense(&mut state, surface, &series.inputs(i))?))
        })
        .collect()
}

/// Thresholds of [`analyse`]; the defaults are the documented method.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Folds for held-out scores (in the two layouts of the crate documentation's step 5).
    pub folds: usize,
    /// Rounds of name-and-add.
    pub max_rounds: usize,
    /// The residual is at the noise floor when its in-contact RMS ≤ floor_margin·σ (and it is nearly white:
    /// lag-1 autocorrelation ≤ [`Options::max_white_rho`]). 1.2 lets a structure of up to 0.66 σ hide in
    /// the noise: smaller than any effect worth naming, larger than the error of σ from a second of free
    /// space.
    pub floor_margin: f64,
    pub max_white_rho: f64,
    /// Smallest relative improvement of the held-out MSE (0.05 = 5 %).
    pub min_gain: f64,
    /// Smallest share of the current excess held-out MSE (over σ²) an accepted option must explain. A
    /// candidate that explains a small part of a large structured residual is the nearest proxy of an
    /// effect outside the library, not a discovery: 0.35 demands it explain a third of what is there
    /// (three effects of similar size, as in the demo's sponge, each explain about that much in turn).
    pub min_share: f64,
    /// Smallest AICc decrease (10: "very strong" on Burnham and Anderson's scale).
    pub min_delta_aicc: f64,
    /// Smallest |t| of every new amplitude, with the autocorrelation-inflated variance.
    pub min_t: f64,
    /// |corr| of two candidates' fitted contributions beyond which they are collinear.
    pub collinear_corr: f64,
    /// Held-out scores within this factor "explain nearly as much" (PySR's 1.5×).
    pub rival_ratio: f64,
    /// How long a tare reads the sensor \[s\] (the F/T node's `bias_window`): the time scale of
    /// [`NoiseFloor::level_sigma`].
    pub tare_window: f64,
    /// A slow offset (a sensor bias, a sensor drift, a drifting surface zero) is named only where it moves
    /// the force by more than this many [`NoiseFloor::level_sigma`]: less is what a tare's own reading or a
    /// slow noise leaves.
    pub level_margin: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            folds: 5,
            max_rounds: 4,
            floor_margin: 1.2,
            max_white_rho: 0.5,
            min_gain: 0.05,
            min_share: 0.35,
            min_delta_aicc: 10.0,
            min_t: 3.0,
            collinear_corr: 0.9,
            rival_ratio: 1.5,
            tare_window: 0.1,
            level_margin: 3.0,
        }
    }
}

/// The whole workflow: phases, noise floor, baseline gap, naming, adding; see the crate documentation.
/// Its steps read top to bottom here; each is a method of `analysis::Analysis` (analysis.rs).
pub fn analyse(series: &Series, baseline: &ContactModel, options: &Options) -> Result<Report, DiscrepancyError> {
    series.validate()?;
    baseline.validate()?;
    let in_contact = series.z.iter().filter(|&&z| z > 0.0).count();
    if series.len() < MIN_SAMPLES.max(10 * options.folds) || in_contact < MIN_CONTACT_SAMPLES {
        return Err(DiscrepancyError::TooShort { got: series.len(), in_contact });
    }
    // A model whose forces on this record overflow (a parameter out of all proportion) leaves no residual
    // to explain.
    let given_rms = law::whole_rms(series, baseline, 0.0)?;
    if !given_rms.is_finite() {
        return Err(ContactError::InvalidModel(
            "its forces on this record overflow: a parameter is out of all proportion".into(),
        )
        .into());
    }
    let velocity = velocity_threshold(series);
    let on_law = |law: &ContactModel| -> Result<Report, DiscrepancyError> {
        let mut analysis = Analysis::refit_baseline(series, baseline, law, options, velocity)?;
        analysis.name_and_add()?;
        analysis.polish_once_more()?;
        analysis.undo_rounds_that_simulate_worse();
        analysis.try_the_quasi_linear_form()?;
        analysis.try_the_medium()?;
        analysis.drop_shapes_at_an_edge()?;
        analysis.keep_the_baseline_if_better(given_rms)?;
        analysis.report()
    };
    let report = on_law(baseline)?;
    // A wrong kind is fixed, not patched: a rival kind replaces it where it fits better before and after.
    let (held_out_rms_from, rivals) = law::rivals(series, baseline, options)?;
    let final_rms = |r: &Report| law::whole_rms(series, &r.model, r.contact_shift);
    let final_rms_from = if rivals.is_empty() { 0.0 } else { final_rms(&report)? };
    for rival in rivals {
        let other = on_law(&rival.law)?;
        let final_rms_to = final_rms(&other)?;
        if !other.kept_baseline && final_rms_to < final_rms_from * (1.0 - options.min_gain) {
            let choice = LawChoice {
                from: baseline.kind,
                to: rival.law.kind,
                held_out_rms_from,
                held_out_rms_to: rival.held_out_rms,
                final_rms_from,
                final_rms_to,
            };
            return Ok(Report { law_rechosen: Some(choice), ..other });
        }
    }
    Ok(report)
}
