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
//!    `contact_offset_drift`). For a shape parameter on a grid (τ, v₀, a′) the model is linear in its
//!    amplitudes; each candidate is fitted **jointly** with k and λ (and the effects already accepted) on
//!    columns scaled to unit RMS. A candidate (or a pair of candidates, so that two hidden effects do not
//!    mask each other) is accepted only if, against the current model:
//!    - its held-out MSE over [`Options::folds`] folds contiguous in time improves by at least
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
//!      of the best one's: then the pair is reported `ambiguous` with the excitation that would separate it,
//!      and nothing is named from it.
//! 6. **Iterate**: add the accepted effect (the best single one; a pair only when no single passes), refit
//!    everything with the surface position, drop an earlier effect the new one made redundant, repeat (at
//!    most [`Options::max_rounds`]); then polish every shape (τ, v₀) in the final structure.
//!    The end is `none` (at the noise floor), `unexplained` (structured residual no candidate explains —
//!    an effect outside the library ends here) or `ambiguous`.
//! 7. **Add**: the augmented [`ContactModel`] (same type; `stiffness_exponent` makes the kind `general`)
//!    is re-simulated with [`ContactModel::step`] for the RMS after, overall and per phase.
//!
//! The lessons behind these choices (columns made dimensionless, joint fits, blocked folds, AICc, margins,
//! collinearity, refusing out-of-library effects) are summarised in the crate's README.md (crates/discrepancy).
//!
//! # Files, in the order the workflow uses them
//! `series.rs` (the samples, checked) → `phase.rs` (phases, noise floor) → `scales.rs` (the record's
//! scales: shape grids, floors, bounds) → `fit.rs` (the linear columns and the joint fit, held-out by
//! folds) → `family.rs` (the library as screened: id, term, grid) → `candidate.rs` (one candidate fitted
//! and judged, the rules it must pass) → `refine.rs` (the named shapes refined together) →
//! `augmented.rs` (the augmented model, its simulated gap, the surface, parameters and intervals) →
//! `report.rs` (what is reported, where the gap is); [`analyse`] below runs the rounds. Beside it:
//! `wrench.rs` (every wrench channel), `arm.rs` (the arm's own effects), `loading_paths.rs` (tangential
//! path effects).

mod arm;
mod augmented;
mod candidate;
mod family;
mod fit;
mod loading_paths;
mod phase;
mod refine;
mod report;
mod scales;
mod series;
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
    #[error("baseline model: {0}")]
    Model(#[from] ContactError),
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
    /// Folds contiguous in time for held-out scores.
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
    /// How long a tare reads the sensor [s] (the F/T node's `bias_window`): the time scale of
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
pub fn analyse(series: &Series, baseline: &ContactModel, options: &Options) -> Result<Report, DiscrepancyError> {
    series.validate()?;
    baseline.validate()?;
    let in_contact = series.z.iter().filter(|&&z| z > 0.0).count();
    if series.len() < MIN_SAMPLES.max(10 * options.folds) || in_contact < MIN_CONTACT_SAMPLES {
        return Err(DiscrepancyError::TooShort { got: series.len(), in_contact });
    }
    let o = options;
    let v_th = velocity_threshold(series);
    let fscale = series.f.iter().map(|f| f.abs()).fold(0.0, f64::max);
    let scales = Scales::of(series, v_th);

    // The baseline's k, λ and the surface position refitted (the position's column stays in every later
    // fit), then the samples re-masked where the refitted law clamps at zero, and refitted once more.
    let d = Data::new(series, o.folds, baseline);
    let ex = baseline.exponents;
    let start = Structure {
        a: ex.a,
        b: ex.b,
        c: ex.c,
        shift: 0.0,
        offset_rate: 0.0,
        delay: 0.0,
        terms: vec![Term::Shift],
        clamped: d.clamped.clone(),
    };
    let mut order: Vec<(Family, f64)> = vec![];
    let (mut st, _, _) = refine_surface(&d, &start);
    st.clamped =
        clamp_mask(&to_model(baseline, d.lateral_axis, &st, &fit::fit(&d, &st), &order), &series.shifted(st.shift))?;
    let (refined, mut shift_se, _) = refine_surface(&d, &st);
    st = refined;
    let mut cur = fit::fit(&d, &st);
    let mut model = to_model(baseline, d.lateral_axis, &st, &cur, &order);

    // Phases and the noise floor at the refitted surface (recomputed when it moves): samples the given
    // surface put in free space but that carry contact force would otherwise inflate σ.
    let at_surface = |shift: f64| {
        let shifted = series.shifted(shift);
        let ph = phases(&shifted, v_th);
        let noise = noise_floor(&shifted, &ph, o.tare_window);
        let free: Vec<usize> = (0..series.len()).filter(|&i| !ph[i].in_contact()).collect();
        (ph, noise, free)
    };
    let (mut ph, mut noise, mut free) = at_surface(st.shift);
    let sigma_of = |noise: &NoiseFloor| noise.sigma.max(1e-9 * fscale).max(1e-300);
    let mut sigma = sigma_of(&noise);
    let free_mse = |free: &[usize], pred: &[f64]| -> f64 {
        free.iter().map(|&i| (series.f[i] - pred[i]).powi(2)).sum::<f64>() / free.len().max(1) as f64
    };

    let mut cur_gap = gap(series, &ph, &simulate(&model, &series.shifted(st.shift))?);
    let (refit_model, refit_shift) = (model.clone(), st.shift);
    let refit = Refit {
        stiffness: model.stiffness,
        damping: model.damping,
        contact_shift: st.shift,
        contact_shift_ci: 1.96 * shift_se,
        rms: cur_gap.rms,
    };
    let mut stages: Vec<(f64, f64)> = vec![]; // (rms_before, rms_after) per accepted family
    let mut rate_se = 0.0;
    let mut ambiguous = vec![];
    let mut forms: Vec<Ambiguity> = vec![];
    let mut form_rivals: Vec<Ambiguity> = vec![];
    // At the floor in contact and out of it: a linear law's refitted surface absorbs a sensor offset in
    // contact, and only free space shows it.
    let at_floor = |g: &Gap, sigma: f64| g.rms.max(g.free_rms) <= o.floor_margin * sigma && g.lag1 <= o.max_white_rho;

    let mut polished = false;
    let mut rounds = 0;
    // The state before every accepted round: the last rounds are undone while what they named, simulated,
    // fits worse than the model before them (the linear columns a candidate is judged on and the model's
    // own stepping can part where the law clamps; a round in the middle may pass through worse on its way).
    let mut history = vec![];
    'rounds: while rounds < o.max_rounds {
        // What this round starts from (see `history`).
        let start_of_round =
            (st.clone(), cur.clone(), order.clone(), stages.clone(), cur_gap.clone(), shift_se, rate_se);
        if at_floor(&cur_gap, sigma) {
            break;
        }
        // Each family once, but relaxation up to twice: real elastomers relax on several time scales (a fast
        // and a slow Maxwell branch are one effect id with two time constants).
        // Relaxation is screened in its Maxwell form; its quasi-linear form is tried once the branches are
        // named (below).
        let times = |f: Family| order.iter().filter(|x| x.0 == f).count();
        let left: Vec<Family> = Family::ALL
            .into_iter()
            .filter(|&f| f != Family::QuasiLinear)
            .filter(|&f| times(f) < if f == Family::Relaxation { MAX_RELAXATION_BRANCHES } else { 1 })
            .filter(|&f| f.observable(&d))
            .collect();
        let singles: Vec<Cand> = left.iter().map(|&f| screen(&d, &st, f, &scales, cur.cv_mse)).collect();
        // A candidate must not fit free space worse than the current model: there the force is the sensor's
        // alone, and an offset that helps in contact but not there stands in for the surface position. Each
        // stretch of free space on its own too: a drift that follows an adhesion pulling after lift-off makes
        // the clean approach before it worse.
        let stretches: Vec<&[usize]> =
            free.chunk_by(|a, b| b == &(a + 1)).filter(|run| run.len() >= MIN_NOISE_SAMPLES).collect();
        let free_ok = |c: &Cand| {
            let no_worse =
                |idx: &[usize]| free_mse(idx, &c.fit.pred) <= 1.5 * free_mse(idx, &cur.pred).max(sigma * sigma);
            free.is_empty() || (no_worse(&free) && stretches.iter().all(|run| no_worse(run)))
        };
        let global = |c: &Cand| {
            c.fit.cv_mse <= cur.cv_mse * (1.0 - o.min_gain)
                && cur.cv_mse - c.fit.cv_mse >= o.min_share * (cur.cv_mse - sigma * sigma)
                && c.t.iter().all(|t| t.abs() >= o.min_t)
        };
        let cur_held = std::cell::OnceCell::new();
        let local = |c: &Cand| {
            let before = cur_held.get_or_init(|| fit::held_out(&d, &st));
            phase_local(&ph, before, &fit::held_out(&d, &c.st), sigma, o)
        };
        let passes = |c: &Cand| {
            c.physical
                && free_ok(c)
                && slow_offsets_material(&d, c, o.level_margin * noise.level_sigma, &stretches)
                && c.fit.aicc <= cur.aicc - o.min_delta_aicc
                && c.stable.iter().all(|&s| s)
                && (global(c) || local(c))
        };
        // One effect at a time while one passes (the next round judges the rest at the surface and noise
        // floor this one moves); pairs only when no single does, so that two effects that mask each other
        // (each one's residual autocorrelation deflating the other's t) are still found.
        let mut options: Vec<Cand> = singles.iter().filter(|c| passes(c)).cloned().collect();
        for i in 0..singles.len() * usize::from(options.is_empty()) {
            for j in i + 1..singles.len() {
                // Pairs are for effects of the surface that mask each other; a delay reads everything late
                // and, paired, becomes a small correction of whatever the other member leaves.
                if [i, j].iter().any(|&k| singles[k].fams[0].0 == Family::TimeDelay) {
                    continue;
                }
                let pair = assess(&d, &st, &[singles[i].fams[0], singles[j].fams[0]], &scales);
                let best_single = singles[i].fit.cv_mse.min(singles[j].fit.cv_mse);
                if passes(&pair) && pair.fit.cv_mse <= best_single * (1.0 - o.min_gain) {
                    options.push(pair);
                }
            }
        }
        let accepted = 'round: {
            let Some(best) = options.into_iter().min_by(|a, b| a.fit.cv_mse.total_cmp(&b.fit.cv_mse)) else {
                break 'round false;
            };
            // Collinear rivals: judged on the single-family fits.
            let gain = |c: &Cand| cur.cv_mse - c.fit.cv_mse;
            let contribution =
                |c: &Cand| -> Vec<f64> { c.fit.pred.iter().zip(&cur.pred).map(|(a, b)| a - b).collect() };
            let mut found = vec![];
            for &(f, _) in &best.fams {
                let Some(mine) = singles.iter().find(|c| c.fams[0].0 == f) else { continue };
                let cm = contribution(mine);
                for rival in singles.iter().filter(|c| best.fams.iter().all(|x| x.0 != c.fams[0].0)) {
                    if corr(&cm, &contribution(rival)).abs() > o.collinear_corr
                        && rival.fit.cv_mse <= o.rival_ratio * mine.fit.cv_mse
                        && gain(rival) * o.rival_ratio >= gain(mine)
                    {
                        found.push((f, rival.fams[0].0));
                    }
                }
            }
            // Rivals that are both forms of the surface's dissipation: the best is named, the other reported.
            let forms_only = found.iter().all(|&(f, r)| f.dissipative() && r.dissipative());
            for &(f, r) in &found {
                let known = |a: &Ambiguity| a.between.contains(&r.id().to_string());
                if !ambiguous.iter().any(known) && !forms.iter().any(known) {
                    let entry = Ambiguity {
                        between: [f.id().to_string(), r.id().to_string()],
                        would_separate: would_separate(f, r),
                        named: forms_only.then(|| f.id().to_string()),
                    };
                    if forms_only { forms.push(entry) } else { ambiguous.push(entry) }
                }
            }
            if !ambiguous.is_empty() {
                break 'rounds;
            }
            // Accept, larger gain first within a pair.
            let mut fams = best.fams.clone();
            if fams.len() == 2 {
                let g: Vec<f64> =
                    fams.iter().map(|x| singles.iter().find(|c| c.fams[0].0 == x.0).map_or(0.0, gain)).collect();
                if g[1] > g[0] {
                    fams.swap(0, 1);
                }
            }
            let (next, se_shift, se_rate) = refine_surface(&d, &best.st);
            // A surface moved past the deepest samples leaves nothing in contact to judge: not an effect.
            if series.shifted(next.shift).z.iter().filter(|&&z| z > 0.0).count() < MIN_CONTACT_SAMPLES {
                break 'round false;
            }
            shift_se = se_shift;
            if fams.iter().any(|x| x.0 == Family::OffsetDrift) {
                rate_se = se_rate;
            }
            for (n, &fam) in fams.iter().enumerate() {
                // Each member's own gap: the intermediate model with the members so far.
                let partial =
                    if n + 1 == fams.len() { next.clone() } else { refine_surface(&d, &fam.0.apply(&st, fam.1)).0 };
                let pf = fit::fit(&d, &partial);
                order.push(fam);
                let m = to_model(baseline, d.lateral_axis, &partial, &pf, &order);
                let g = gap(series, &ph, &simulate(&m, &series.shifted(partial.shift))?);
                stages.push((cur_gap.rms, g.rms));
                cur_gap = g;
            }
            st = next;
            cur = fit::fit(&d, &st);
            // Backward check: an effect accepted in an earlier round may have stood in for what this round
            // named (a moving surface zero for a slow relaxation branch); drop it when the model without it
            // is held-out nearly as good.
            let earlier = order.len() - fams.len();
            for i in (0..earlier).rev() {
                let (f, sh) = order[i];
                let Some(reduced) = f.remove(&st, sh) else { continue };
                let (reduced, _, _) = refine_surface(&d, &reduced);
                let fr = fit::fit(&d, &reduced);
                if fr.cv_mse <= cur.cv_mse * (1.0 + o.min_gain) && fr.aicc <= cur.aicc + o.min_delta_aicc {
                    order.remove(i);
                    stages.remove(i);
                    st = reduced;
                    cur = fr;
                }
            }
            // The shapes of the effects named so far, refined together with the new one, before the next
            // round judges what is left (a branch's τ a few per cent off leaves a residual that a proxy
            // second branch would take).
            polish(&d, &mut st, &mut cur, &mut order, &scales, false);
            true
        };
        // Before giving up, polish the shapes in the current structure and look once more: a shape chosen
        // in its own round leaves a misfit that can hide a small effect (the demo's sensor drift).
        if accepted {
            rounds += 1;
            polished = false;
        } else if polished || !polish(&d, &mut st, &mut cur, &mut order, &scales, true) {
            break;
        } else {
            polished = true;
        }
        model = to_model(baseline, d.lateral_axis, &st, &cur, &order);
        // Where the augmented model's force clamps at zero in contact, the linear columns do not hold:
        // re-mask with the augmented model and refit.
        st.clamped = clamp_mask(&model, &series.shifted(st.shift))?;
        // The re-masked fit moves the surface again (its position column would otherwise carry an offset
        // in contact that the model, which knows the surface only by its position, does not have).
        let se_rate;
        (st, shift_se, se_rate) = refine_surface(&d, &st);
        if order.iter().any(|x| x.0 == Family::OffsetDrift) {
            rate_se = se_rate;
        }
        cur = fit::fit(&d, &st);
        model = to_model(baseline, d.lateral_axis, &st, &cur, &order);
        model.validate()?;
        (ph, noise, free) = at_surface(st.shift);
        sigma = sigma_of(&noise);
        cur_gap = gap(series, &ph, &simulate(&model, &series.shifted(st.shift))?);
        if let Some(last) = stages.last_mut() {
            last.1 = cur_gap.rms;
        }
        if accepted {
            history.push(start_of_round);
        }
    }

    if !polished && ambiguous.is_empty() && polish(&d, &mut st, &mut cur, &mut order, &scales, true) {
        model = to_model(baseline, d.lateral_axis, &st, &cur, &order);
        st.clamped = clamp_mask(&model, &series.shifted(st.shift))?;
        // The re-masked fit moves the surface again (its position column would otherwise carry an offset
        // in contact that the model, which knows the surface only by its position, does not have).
        let se_rate;
        (st, shift_se, se_rate) = refine_surface(&d, &st);
        if order.iter().any(|x| x.0 == Family::OffsetDrift) {
            rate_se = se_rate;
        }
        cur = fit::fit(&d, &st);
        model = to_model(baseline, d.lateral_axis, &st, &cur, &order);
        model.validate()?;
        cur_gap = gap(series, &ph, &simulate(&model, &series.shifted(st.shift))?);
        if let Some(last) = stages.last_mut() {
            last.1 = cur_gap.rms;
        }
    }

    while stages.last().is_some_and(|&(before, after)| after > before * (1.0 + 1e-3)) {
        let Some(start) = history.pop() else { break };
        (st, cur, order, stages, cur_gap, shift_se, rate_se) = start;
        model = to_model(baseline, d.lateral_axis, &st, &cur, &order);
        (ph, noise, _) = at_surface(st.shift);
        sigma = sigma_of(&noise);
    }

    // The relaxation's form: the branches named on the deformation (Maxwell) tried on the law's elastic
    // force (Fung's quasi-linear form), polished there; taken where it predicts held-out data better by
    // the gain a new effect needs and the simulated gap closes further.
    if ambiguous.is_empty() && order.iter().any(|x| x.0 == Family::Relaxation) {
        let mut quasi = st.clone();
        for t in quasi.terms.iter_mut() {
            if let Term::Relax(tau) = *t {
                *t = Term::QuasiRelax(tau);
            }
        }
        let mut quasi_order: Vec<(Family, f64)> =
            order.iter().map(|&(f, sh)| (if f == Family::Relaxation { Family::QuasiLinear } else { f }, sh)).collect();
        let (mut quasi, _, _) = refine_surface(&d, &quasi);
        let mut quasi_fit = fit::fit(&d, &quasi);
        polish(&d, &mut quasi, &mut quasi_fit, &mut quasi_order, &scales, false);
        if quasi_fit.cv_mse <= cur.cv_mse * (1.0 - o.min_gain) {
            let m = to_model(baseline, d.lateral_axis, &quasi, &quasi_fit, &quasi_order);
            m.validate()?;
            let g = gap(series, &ph, &simulate(&m, &series.shifted(quasi.shift))?);
            if g.rms < cur_gap.rms {
                (st, cur, order, model, cur_gap) = (quasi, quasi_fit, quasi_order, m, g);
                if let Some(last) = stages.last_mut() {
                    last.1 = cur_gap.rms;
                }
                (ph, noise, _) = at_surface(st.shift);
                sigma = sigma_of(&noise);
            }
        }
    }

    // A shape still at an end of its range after every polish is a bound, not a finding: the effect is
    // dropped (the model refitted without it) and reported among `bounds`.
    let mut bounds = vec![];
    while let Some(i) = order.iter().position(|&(f, sh)| scales.at_edge(f, sh).is_some()) {
        let (f, sh) = order[i];
        let reduced = match f {
            Family::StiffnessExponent => Some(Structure { a: baseline.exponents.a, ..st.clone() }),
            _ => f.remove(&st, sh),
        };
        let Some(reduced) = reduced else { break };
        order.remove(i);
        stages.remove(i);
        bounds.push(Bound { id: f.id().to_string(), shape: sh, range: scales.at_edge(f, sh).unwrap_or_default() });
        (st, shift_se, _) = refine_surface(&d, &reduced);
        cur = fit::fit(&d, &st);
        model = to_model(baseline, d.lateral_axis, &st, &cur, &order);
        model.validate()?;
        cur_gap = gap(series, &ph, &simulate(&model, &series.shifted(st.shift))?);
        if let Some(last) = stages.last_mut() {
            last.1 = cur_gap.rms;
        }
    }

    let base_gap = gap(series, &ph, &simulate(baseline, series)?);
    // Never worse than the model the user gave (or identify found): where the refitted and augmented
    // model fits the contact, or free space, worse than that baseline as it was given, the baseline stands
    // and nothing is named.
    // Judged on every sample, in contact or not, so that neither model's surface decides which count.
    let whole_rms = |m: &ContactModel, shift: f64| -> Result<f64, DiscrepancyError> {
        let pred = simulate(m, &series.shifted(shift))?;
        Ok((pred.iter().zip(&series.f).map(|(p, f)| (f - p).powi(2)).sum::<f64>() / series.len() as f64).sqrt())
    };
    let kept_baseline = whole_rms(&model, st.shift)? > whole_rms(baseline, 0.0)?;
    if kept_baseline {
        order.clear();
        stages.clear();
        ambiguous.clear();
        bounds.clear();
        model = baseline.clone();
        st.shift = 0.0;
        shift_se = 0.0;
        cur_gap = base_gap.clone();
    }
    // A form named over its rival is reported while the model still carries it (in either relaxation form).
    for mut a in forms {
        let named = order.iter().map(|x| x.0).find(|&f| {
            a.named.as_deref() == Some(f.id())
                || (f == Family::QuasiLinear && a.named.as_deref() == Some(Family::Relaxation.id()))
        });
        if let Some(f) = named {
            a.named = Some(f.id().to_string());
            a.between[0] = f.id().to_string();
            form_rivals.push(a);
        }
    }
    let remaining = if !ambiguous.is_empty() {
        Remaining::Ambiguous
    } else if at_floor(&cur_gap, sigma) {
        Remaining::None
    } else {
        Remaining::Unexplained
    };
    let duration = series.t.last().copied().unwrap_or(0.0) - series.t.first().copied().unwrap_or(0.0);
    let effects = order
        .iter()
        .zip(&stages)
        .map(|(&(f, sh), &(before, after))| {
            let parameters = parameters(&model, f, sh);
            let uncertainty = uncertainty(&d, &st, &cur, f, sh, rate_se);
            let not_identifiable = parameters
                .iter()
                .filter(|(k, v)| {
                    uncertainty
                        .get(*k)
                        .is_some_and(|u| !u.is_finite() || *u > v.abs() || (k.ends_with("_s") && *u > duration))
                })
                .map(|(k, _)| k.clone())
                .collect();
            NamedEffect {
                id: f.id().to_string(),
                parameters,
                uncertainty,
                not_identifiable,
                rms_before: before,
                rms_after: after,
            }
        })
        .collect();
    let phases_out = base_gap
        .phases
        .iter()
        .map(|(&p, &before)| (p, PhaseRms { rms_before: before, rms_after: cur_gap.phases[&p] }))
        .collect();
    Ok(Report {
        baseline: Baseline { kind: baseline.kind, rms: base_gap.rms },
        refit,
        noise_floor: sigma,
        noise_source: noise.source,
        level_noise: noise.level_sigma,
        effects,
        ambiguous: ambiguous.into_iter().chain(form_rivals).collect(),
        phases: phases_out,
        final_rms: cur_gap.rms,
        locate: {
            let residual = |m: &ContactModel, shift: f64| -> Result<Vec<f64>, DiscrepancyError> {
                Ok(simulate(m, &series.shifted(shift))?.iter().zip(&series.f).map(|(p, f)| f - p).collect())
            };
            let given = simulate(baseline, series)?;
            let mut l =
                locate(series, &ph, &given, &residual(&refit_model, refit_shift)?, &residual(&model, st.shift)?);
            if let Some(w) = &series.wrench {
                let before = predict_wrench(&refit_model, &series.shifted(refit_shift), w)?;
                let after = predict_wrench(&model, &series.shifted(st.shift), w)?;
                l.channels = wrench::channels(series, &ph, w, &before, &after);
            }
            l
        },
        contact_shift: st.shift,
        contact_shift_ci: 1.96 * shift_se,
        remaining,
        model,
        velocity_threshold: v_th,
        final_lag1: cur_gap.lag1,
        kept_baseline,
        bounds,
    })
}
