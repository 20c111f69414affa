//! The steps of [`crate::analyse`], each a method of [`Analysis`], in the order it runs them:
//! [`Analysis::refit_baseline`] (k, λ and the surface refitted, the phases and noise floor at that surface)
//! → [`Analysis::name_and_add`] (the rounds: screen every family, judge, name the best, add it, refit) →
//! [`Analysis::polish_once_more`] → [`Analysis::undo_rounds_that_simulate_worse`] →
//! [`Analysis::try_the_quasi_linear_form`] → [`Analysis::try_the_medium`] (`analysis/medium.rs`) →
//! [`Analysis::drop_shapes_at_an_edge`] →
//! [`Analysis::keep_the_baseline_if_better`] → [`Analysis::report`].

use std::cell::OnceCell;

use softcontact_contact::ContactModel;

use crate::fit::{self, Data, Fit, Structure, Term};
use crate::law::whole_rms;
use crate::{
    Ambiguity, Baseline, Bound, Cand, DiscrepancyError, Family, Gap, NamedEffect, NoiseFloor, Options, Phase, PhaseRms,
    Refit, Remaining, Report, Scales, Series, assess, clamp_mask, corr, gap, locate, noise_floor, parameters,
    phase_local, phases, polish, predict_wrench, refine_surface, screen, simulate, slow_offsets_material, to_model,
    uncertainty, would_separate,
};
use crate::{MAX_RELAXATION_BRANCHES, MIN_CONTACT_SAMPLES, MIN_NOISE_SAMPLES, wrench};

mod medium;

/// What a round changes, kept whole so that a round can be undone.
#[derive(Clone)]
struct Progress {
    /// The linear structure (exponents, surface shift, terms, clamp mask) and its joint fit.
    structure: Structure,
    fit: Fit,
    /// The effects named so far, in order, each with its shape (τ, v₀, a′, …).
    named: Vec<(Family, f64)>,
    /// (RMS before, RMS after) of the simulated gap, one per named effect.
    stages: Vec<(f64, f64)>,
    /// The simulated gap of the current model.
    gap: Gap,
    /// Standard errors of the surface shift and (with a contact-offset drift) of its rate.
    shift_se: f64,
    rate_se: f64,
}

/// What the surface position decides: the phases, the noise floor and the free samples.
struct AtSurface {
    phases: Vec<Phase>,
    noise: NoiseFloor,
    free: Vec<usize>,
    /// The noise floor's σ, never zero.
    sigma: f64,
}

/// One analysis: the record, the baseline and the method's thresholds, and what the steps move.
pub(crate) struct Analysis<'a> {
    series: &'a Series,
    /// The baseline as given: what the result is never worse than, and what the report compares with.
    given: &'a ContactModel,
    /// The law the structure is built on: the given one, or another kind's ([`crate::law`]).
    law: ContactModel,
    options: &'a Options,
    data: Data<'a>,
    scales: Scales,
    velocity_threshold: f64,
    /// The largest |force|: σ is at least 1e-9 of it.
    force_scale: f64,
    now: Progress,
    model: ContactModel,
    surface: AtSurface,
    /// Rivals that name nothing (the answer is `ambiguous`).
    ambiguous: Vec<Ambiguity>,
    /// Rivals that are both forms of the surface's dissipation: the better one is named.
    forms: Vec<Ambiguity>,
    /// Whether the shapes were polished since the last accepted round.
    polished: bool,
    /// The progress before every accepted round (see [`Analysis::undo_rounds_that_simulate_worse`]).
    history: Vec<Progress>,
    /// The refitted baseline, as reported and as `locate` compares.
    refit: Refit,
    refit_model: ContactModel,
    bounds: Vec<Bound>,
    kept_baseline: bool,
}

impl<'a> Analysis<'a> {
    /// The law's k, λ and the surface position refitted ([`refit_law`]); the phases and the noise floor
    /// at the refitted surface (recomputed whenever it moves): samples the given surface put in free space
    /// but that carry contact force would otherwise inflate σ. `law` is `given`, or the law of another
    /// kind [`crate::law::rivals`] found.
    pub(crate) fn refit_baseline(
        series: &'a Series,
        given: &'a ContactModel,
        law: &ContactModel,
        options: &'a Options,
        velocity_threshold: f64,
    ) -> Result<Self, DiscrepancyError> {
        let force_scale = series.f.iter().map(|f| f.abs()).fold(0.0, f64::max);
        let scales = Scales::of(series, velocity_threshold);
        let data = Data::new(series, options.folds, options.tare_window, law);
        let (structure, shift_se, fit) = refit_law(&data, law)?;
        let model = to_model(law, &data, &structure, &fit, &[]);
        let surface = at_surface(series, options, velocity_threshold, force_scale, structure.shift);
        let gap = gap(series, &surface.phases, &simulate(&model, &series.shifted(structure.shift))?);
        let refit = Refit {
            kind: law.kind,
            stiffness: model.stiffness,
            damping: model.damping,
            contact_shift: structure.shift,
            contact_shift_ci: 1.96 * shift_se,
            contact_shift_identifiable: crate::shift_identifiable(series, 1.96 * shift_se),
            rms: gap.rms,
        };
        Ok(Analysis {
            series,
            given,
            law: law.clone(),
            options,
            data,
            scales,
            velocity_threshold,
            force_scale,
            now: Progress { structure, fit, named: vec![], stages: vec![], gap, shift_se, rate_se: 0.0 },
            refit_model: model.clone(),
            model,
            surface,
            ambiguous: vec![],
            forms: vec![],
            polished: false,
            history: vec![],
            refit,
            bounds: vec![],
            kept_baseline: false,
        })
    }

    /// At the floor in contact and out of it: a linear law's refitted surface absorbs a sensor offset in
    /// contact, and only free space shows it.
    fn at_floor(&self, gap: &Gap) -> bool {
        let o = self.options;
        gap.rms.max(gap.free_rms) <= o.floor_margin * self.surface.sigma && gap.lag1 <= o.max_white_rho
    }

    fn model_of(&self, structure: &Structure, fit: &Fit, named: &[(Family, f64)]) -> ContactModel {
        to_model(&self.law, &self.data, structure, fit, named)
    }

    /// The simulated gap of `model` with the surface moved by `shift`, over the current phases.
    fn gap_of(&self, model: &ContactModel, shift: f64) -> Result<Gap, DiscrepancyError> {
        Ok(gap(self.series, &self.surface.phases, &simulate(model, &self.series.shifted(shift))?))
    }

    /// The current model's gap, which also closes the last named effect's stage.
    fn update_gap(&mut self) -> Result<(), DiscrepancyError> {
        self.now.gap = self.gap_of(&self.model, self.now.structure.shift)?;
        if let Some(last) = self.now.stages.last_mut() {
            last.1 = self.now.gap.rms;
        }
        Ok(())
    }

    fn move_surface(&mut self) {
        let s = self.series;
        self.surface = at_surface(s, self.options, self.velocity_threshold, self.force_scale, self.now.structure.shift);
    }

    /// The rounds: each family screened against the current model, the best that passes every rule named
    /// and added (a pair only when no single passes), the model refitted; a round that names nothing
    /// polishes the shapes once and looks again. Ends at the noise floor, after
    /// [`Options::max_rounds`], with nothing left to name, or with rivals that leave the answer
    /// `ambiguous`.
    pub(crate) fn name_and_add(&mut self) -> Result<(), DiscrepancyError> {
        let mut rounds = 0;
        while rounds < self.options.max_rounds {
            let start_of_round = self.now.clone();
            if self.at_floor(&self.now.gap) {
                break;
            }
            let accepted = match self.round()? {
                Round::Named => true,
                Round::NothingNamed => false,
                Round::Ambiguous => break,
            };
            // Before giving up, polish the shapes in the current structure and look once more: a shape
            // chosen in its own round leaves a misfit that can hide a small effect (the demo's sensor drift).
            if accepted {
                rounds += 1;
                self.polished = false;
            } else if self.polished || !self.polish(true) {
                break;
            } else {
                self.polished = true;
            }
            self.remask_and_refit()?;
            self.move_surface();
            self.update_gap()?;
            if accepted {
                self.history.push(start_of_round);
            }
        }
        Ok(())
    }

    fn polish(&mut self, regrid: bool) -> bool {
        let now = &mut self.now;
        polish(&self.data, &mut now.structure, &mut now.fit, &mut now.named, &self.scales, regrid)
    }

    /// One round: every family left screened, judged, and the best option added.
    fn round(&mut self) -> Result<Round, DiscrepancyError> {
        let candidates = self.screen_families();
        let stretches = self.free_stretches();
        let held_now = OnceCell::new();
        // One effect at a time while one passes (the next round judges the rest at the surface and noise
        // floor this one moves); pairs only when no single does, so that two effects that mask each other
        // (each one's residual autocorrelation deflating the other's t) are still found.
        let mut options: Vec<Cand> =
            candidates.iter().filter(|c| self.passes(c, &stretches, &held_now)).cloned().collect();
        if options.is_empty() {
            options = self.pairs_that_pass(&candidates, &stretches, &held_now);
        }
        let Some(best) = options.into_iter().min_by(|a, b| a.fit.cv_mse.total_cmp(&b.fit.cv_mse)) else {
            return Ok(Round::NothingNamed);
        };
        self.note_rivals(&best, &candidates);
        if !self.ambiguous.is_empty() {
            return Ok(Round::Ambiguous);
        }
        Ok(if self.add(best, &candidates)? { Round::Named } else { Round::NothingNamed })
    }

    /// Each family once, but relaxation up to twice: real elastomers relax on several time scales (a fast
    /// and a slow Maxwell branch are one effect id with two time constants). Relaxation is screened in its
    /// Maxwell form; its quasi-linear form is tried once the branches are named
    /// ([`Analysis::try_the_quasi_linear_form`]).
    ///
    /// The delay's screen reads every column late, at three masks a delay, and costs about as much as the
    /// others together (325 of 690 ms on the timing bench's recording): with a second core it runs on a
    /// thread of its own, on a [`Data::detached`] copy. The candidates and their order are the same.
    fn screen_families(&self) -> Vec<Cand> {
        let times = |f: Family| self.now.named.iter().filter(|x| x.0 == f).count();
        let families: Vec<Family> = Family::ALL
            .into_iter()
            .filter(|&f| !matches!(f, Family::QuasiLinear | Family::MediumDrag | Family::SqueezeFilm))
            .filter(|&f| times(f) < if f == Family::Relaxation { MAX_RELAXATION_BRANCHES } else { 1 })
            .filter(|&f| f.observable(&self.data))
            .collect();
        let (st, scales, cv_now) = (&self.now.structure, &self.scales, self.now.fit.cv_mse);
        let two_cores = std::thread::available_parallelism().is_ok_and(|n| n.get() >= 2);
        if !two_cores || !families.contains(&Family::TimeDelay) {
            return families.into_iter().map(|f| screen(&self.data, st, f, scales, cv_now)).collect();
        }
        let detached = self.data.detached();
        std::thread::scope(|scope| {
            let delay = scope.spawn(move || screen(&detached, st, Family::TimeDelay, scales, cv_now));
            let mut rest: Vec<Option<Cand>> = families
                .iter()
                .map(|&f| (f != Family::TimeDelay).then(|| screen(&self.data, st, f, scales, cv_now)))
                .collect();
            let delay = delay.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            let slot = families.iter().position(|&f| f == Family::TimeDelay).expect("screened");
            rest[slot] = Some(delay);
            rest.into_iter().map(|c| c.expect("every family screened")).collect()
        })
    }

    /// The stretches of free space long enough to judge a candidate on.
    fn free_stretches(&self) -> Vec<&[usize]> {
        let free = &self.surface.free;
        free.chunk_by(|a, b| b == &(a + 1)).filter(|run| run.len() >= MIN_NOISE_SAMPLES).collect()
    }

    /// Every rule of a named effect (the crate documentation's step 5); `held_now` caches the current
    /// model's held-out residual for the phase-local rule.
    fn passes(&self, c: &Cand, stretches: &[&[usize]], held_now: &OnceCell<Vec<f64>>) -> bool {
        let (o, cur) = (self.options, &self.now.fit);
        let sigma = self.surface.sigma;
        // A candidate must not fit free space worse than the current model: there the force is the
        // sensor's alone, and an offset that helps in contact but not there stands in for the surface
        // position. Each stretch of free space on its own too: a drift that follows an adhesion pulling
        // after lift-off makes the clean approach before it worse.
        let free_mse = |free: &[usize], pred: &[f64]| -> f64 {
            free.iter().map(|&i| (self.series.f[i] - pred[i]).powi(2)).sum::<f64>() / free.len().max(1) as f64
        };
        let no_worse = |idx: &[usize]| free_mse(idx, &c.fit.pred) <= 1.5 * free_mse(idx, &cur.pred).max(sigma * sigma);
        let free = &self.surface.free;
        let free_ok = free.is_empty() || (no_worse(free) && stretches.iter().all(|run| no_worse(run)));
        // A further relaxation branch names nothing new: it refines an effect already named, which a
        // relaxation spread over decades of time (a polymer's) needs, each branch taking less of the rest.
        let refines = c.fams.iter().all(|(f, _)| *f == Family::Relaxation && self.now.named.iter().any(|x| x.0 == *f));
        let global = || {
            c.fit.cv_mse <= cur.cv_mse * (1.0 - o.min_gain)
                && (refines || cur.cv_mse - c.fit.cv_mse >= o.min_share * (cur.cv_mse - sigma * sigma))
                && c.t.iter().all(|t| t.abs() >= o.min_t)
        };
        let local = || {
            let before = held_now.get_or_init(|| fit::held_out(&self.data, &self.now.structure));
            phase_local(&self.surface.phases, before, &fit::held_out(&self.data, &c.st), sigma, o)
        };
        c.physical
            && free_ok
            && slow_offsets_material(&self.data, c, o.level_margin * self.surface.noise.level_sigma, stretches)
            && c.fit.aicc <= cur.aicc - o.min_delta_aicc
            && c.stable.iter().all(|&s| s)
            && (global() || local())
    }

    /// Pairs of families that pass together and beat the better of their two singles by the gain a new
    /// effect needs.
    fn pairs_that_pass(&self, singles: &[Cand], stretches: &[&[usize]], held_now: &OnceCell<Vec<f64>>) -> Vec<Cand> {
        let mut options = vec![];
        for i in 0..singles.len() {
            for j in i + 1..singles.len() {
                // Pairs are for effects of the surface that mask each other; a delay reads everything late
                // and, paired, becomes a small correction of whatever the other member leaves.
                if [i, j].iter().any(|&k| singles[k].fams[0].0 == Family::TimeDelay) {
                    continue;
                }
                let pair =
                    assess(&self.data, &self.now.structure, &[singles[i].fams[0], singles[j].fams[0]], &self.scales);
                let best_single = singles[i].fit.cv_mse.min(singles[j].fit.cv_mse);
                if self.passes(&pair, stretches, held_now)
                    && pair.fit.cv_mse <= best_single * (1.0 - self.options.min_gain)
                {
                    options.push(pair);
                }
            }
        }
        options
    }

    /// Collinear rivals of the best option, judged on the single-family fits and by the folds contiguous
    /// in time (two effects alike over the record differ by how they extrapolate): rivals that are both
    /// forms of the surface's dissipation go to `forms` (the best is named, the other reported), any other
    /// to `ambiguous` (nothing is named).
    fn note_rivals(&mut self, best: &Cand, singles: &[Cand]) {
        let o = self.options;
        let cur = &self.now.fit;
        let gain = |c: &Cand| cur.stretch_mse - c.fit.stretch_mse;
        let contribution = |c: &Cand| -> Vec<f64> { c.fit.pred.iter().zip(&cur.pred).map(|(a, b)| a - b).collect() };
        let mut found = vec![];
        for &(f, _) in &best.fams {
            let Some(mine) = singles.iter().find(|c| c.fams[0].0 == f) else { continue };
            let cm = contribution(mine);
            // A rival is an effect the record could be: one beyond what it can physically be is none.
            for rival in singles.iter().filter(|c| c.physical && best.fams.iter().all(|x| x.0 != c.fams[0].0)) {
                if corr(&cm, &contribution(rival)).abs() > o.collinear_corr
                    && rival.fit.stretch_mse <= o.rival_ratio * mine.fit.stretch_mse
                    && gain(rival) > 0.0
                    && gain(rival) * o.rival_ratio >= gain(mine)
                {
                    found.push((f, rival.fams[0].0));
                }
            }
        }
        let forms_only = found.iter().all(|&(f, r)| f.dissipative() && r.dissipative());
        for &(f, r) in &found {
            let known = |a: &Ambiguity| a.between.contains(&r.id().to_string());
            if !self.ambiguous.iter().any(known) && !self.forms.iter().any(known) {
                let entry = Ambiguity {
                    between: [f.id().to_string(), r.id().to_string()],
                    would_separate: would_separate(f, r),
                    named: forms_only.then(|| f.id().to_string()),
                };
                if forms_only { self.forms.push(entry) } else { self.ambiguous.push(entry) }
            }
        }
    }

    /// Adds the best option (the larger gain first within a pair), each member with its own gap; drops an
    /// earlier effect the new one made redundant; polishes the shapes. False where the refitted surface
    /// leaves too little in contact to judge.
    fn add(&mut self, best: Cand, singles: &[Cand]) -> Result<bool, DiscrepancyError> {
        let o = self.options;
        let gain = |c: &Cand| self.now.fit.cv_mse - c.fit.cv_mse;
        let mut fams = best.fams.clone();
        if fams.len() == 2 {
            let g: Vec<f64> =
                fams.iter().map(|x| singles.iter().find(|c| c.fams[0].0 == x.0).map_or(0.0, gain)).collect();
            if g[1] > g[0] {
                fams.swap(0, 1);
            }
        }
        let (next, se_shift, se_rate) = refine_surface(&self.data, &best.st);
        // A surface moved past the deepest samples leaves nothing in contact to judge: not an effect.
        if self.series.shifted(next.shift).z.iter().filter(|&&z| z > 0.0).count() < MIN_CONTACT_SAMPLES {
            return Ok(false);
        }
        self.now.shift_se = se_shift;
        if fams.iter().any(|x| x.0 == Family::OffsetDrift) {
            self.now.rate_se = se_rate;
        }
        for (n, &fam) in fams.iter().enumerate() {
            // Each member's own gap: the intermediate model with the members so far.
            let partial = if n + 1 == fams.len() {
                next.clone()
            } else {
                refine_surface(&self.data, &fam.0.apply(&self.now.structure, fam.1)).0
            };
            let partial_fit = fit::fit(&self.data, &partial);
            self.now.named.push(fam);
            let m = self.model_of(&partial, &partial_fit, &self.now.named);
            let g = self.gap_of(&m, partial.shift)?;
            self.now.stages.push((self.now.gap.rms, g.rms));
            self.now.gap = g;
        }
        self.now.structure = next;
        self.now.fit = fit::fit(&self.data, &self.now.structure);
        // Backward check: an effect accepted in an earlier round may have stood in for what this round
        // named (a moving surface zero for a slow relaxation branch); drop it when the model without it is
        // held-out nearly as good.
        let earlier = self.now.named.len() - fams.len();
        for i in (0..earlier).rev() {
            let (f, shape) = self.now.named[i];
            let Some(reduced) = f.remove(&self.now.structure, shape) else { continue };
            let (reduced, _, _) = refine_surface(&self.data, &reduced);
            let reduced_fit = fit::fit(&self.data, &reduced);
            if reduced_fit.cv_mse <= self.now.fit.cv_mse * (1.0 + o.min_gain)
                && reduced_fit.aicc <= self.now.fit.aicc + o.min_delta_aicc
            {
                self.now.named.remove(i);
                self.now.stages.remove(i);
                self.now.structure = reduced;
                self.now.fit = reduced_fit;
            }
        }
        // The shapes of the effects named so far, refined together with the new one, before the next round
        // judges what is left (a branch's τ a few per cent off leaves a residual that a proxy second branch
        // would take).
        self.polish(false);
        Ok(true)
    }

    /// Where the augmented model's force clamps at zero in contact, the linear columns do not hold: re-mask
    /// with the augmented model and refit. The re-masked fit moves the surface again (its position column
    /// would otherwise carry an offset in contact that the model, which knows the surface only by its
    /// position, does not have).
    fn remask_and_refit(&mut self) -> Result<(), DiscrepancyError> {
        self.model = self.model_of(&self.now.structure, &self.now.fit, &self.now.named);
        self.now.structure.clamped = clamp_mask(&self.model, &self.series.shifted(self.now.structure.shift))?;
        let se_rate;
        (self.now.structure, self.now.shift_se, se_rate) = refine_surface(&self.data, &self.now.structure);
        if self.now.named.iter().any(|x| x.0 == Family::OffsetDrift) {
            self.now.rate_se = se_rate;
        }
        self.now.fit = fit::fit(&self.data, &self.now.structure);
        self.model = self.model_of(&self.now.structure, &self.now.fit, &self.now.named);
        self.model.validate()?;
        Ok(())
    }

    /// The shapes polished once more where the rounds ended without doing it.
    pub(crate) fn polish_once_more(&mut self) -> Result<(), DiscrepancyError> {
        if !self.polished && self.ambiguous.is_empty() && self.polish(true) {
            self.remask_and_refit()?;
            self.update_gap()?;
        }
        Ok(())
    }

    /// The last rounds undone while what they named, simulated, fits worse than the model before them (the
    /// linear columns a candidate is judged on and the model's own stepping can part where the law clamps;
    /// a round in the middle may pass through worse on its way).
    pub(crate) fn undo_rounds_that_simulate_worse(&mut self) {
        while self.now.stages.last().is_some_and(|&(before, after)| after > before * (1.0 + 1e-3)) {
            let Some(start) = self.history.pop() else { break };
            self.now = start;
            self.model = self.model_of(&self.now.structure, &self.now.fit, &self.now.named);
            self.move_surface();
        }
    }

    /// The relaxation's form: the branches named on the deformation (Maxwell) tried on the law's elastic
    /// force (Fung's quasi-linear form), polished there; taken where it predicts held-out data better by
    /// the gain a new effect needs and the simulated gap closes further.
    pub(crate) fn try_the_quasi_linear_form(&mut self) -> Result<(), DiscrepancyError> {
        if !self.ambiguous.is_empty() || !self.now.named.iter().any(|x| x.0 == Family::Relaxation) {
            return Ok(());
        }
        let mut quasi = self.now.structure.clone();
        for t in quasi.terms.iter_mut() {
            if let Term::Relax(tau) = *t {
                *t = Term::QuasiRelax(tau);
            }
        }
        let relaxation_as_quasi =
            |&(f, shape): &(Family, f64)| (if f == Family::Relaxation { Family::QuasiLinear } else { f }, shape);
        let mut quasi_named: Vec<(Family, f64)> = self.now.named.iter().map(relaxation_as_quasi).collect();
        let (mut quasi, _, _) = refine_surface(&self.data, &quasi);
        let mut quasi_fit = fit::fit(&self.data, &quasi);
        polish(&self.data, &mut quasi, &mut quasi_fit, &mut quasi_named, &self.scales, false);
        if quasi_fit.cv_mse > self.now.fit.cv_mse * (1.0 - self.options.min_gain) {
            return Ok(());
        }
        let m = self.model_of(&quasi, &quasi_fit, &quasi_named);
        m.validate()?;
        let g = self.gap_of(&m, quasi.shift)?;
        if g.rms < self.now.gap.rms {
            (self.now.structure, self.now.fit, self.now.named, self.model, self.now.gap) =
                (quasi, quasi_fit, quasi_named, m, g);
            if let Some(last) = self.now.stages.last_mut() {
                last.1 = self.now.gap.rms;
            }
            self.move_surface();
        }
        Ok(())
    }

    /// A shape still at an end of its range after every polish is a bound, not a finding: the effect is
    /// dropped (the model refitted without it) and reported among `bounds`. The rows of the effects left
    /// keep what each did when it was named; the final gap is what the drop leaves.
    pub(crate) fn drop_shapes_at_an_edge(&mut self) -> Result<(), DiscrepancyError> {
        while let Some(i) = self.now.named.iter().position(|&(f, sh)| self.scales.at_edge(f, sh).is_some()) {
            let (f, shape) = self.now.named[i];
            let reduced = match f {
                Family::StiffnessExponent => Some(Structure { a: self.law.exponents.a, ..self.now.structure.clone() }),
                _ => f.remove(&self.now.structure, shape),
            };
            let Some(reduced) = reduced else { break };
            self.now.named.remove(i);
            self.now.stages.remove(i);
            let range = self.scales.at_edge(f, shape).unwrap_or_default();
            self.bounds.push(Bound { id: f.id().to_string(), shape, range });
            (self.now.structure, self.now.shift_se, _) = refine_surface(&self.data, &reduced);
            self.now.fit = fit::fit(&self.data, &self.now.structure);
            self.model = self.model_of(&self.now.structure, &self.now.fit, &self.now.named);
            self.model.validate()?;
            self.now.gap = self.gap_of(&self.model, self.now.structure.shift)?;
        }
        Ok(())
    }

    /// Never worse than the model the user gave (or identify found): where the refitted and augmented
    /// model fits the record worse than that baseline as it was given, the baseline stands and nothing is
    /// named. Judged on every sample, in contact or not, so that neither model's surface decides which
    /// count (`given_rms` is the given model's RMS so, [`whole_rms`] at its own surface), and on the
    /// in-contact gap the report compares, each model at its own surface: a model that fits free space
    /// better and the contact worse is not the better one.
    pub(crate) fn keep_the_baseline_if_better(&mut self, given_rms: f64) -> Result<(), DiscrepancyError> {
        let worse_in_contact = self.now.gap.rms > self.gap_of(self.given, 0.0)?.rms;
        self.kept_baseline =
            worse_in_contact || whole_rms(self.series, &self.model, self.now.structure.shift)? > given_rms;
        if self.kept_baseline {
            self.now.named.clear();
            self.now.stages.clear();
            self.ambiguous.clear();
            self.bounds.clear();
            self.model = self.given.clone();
            self.now.structure.shift = 0.0;
            self.now.shift_se = 0.0;
            self.now.gap = self.gap_of(self.given, 0.0)?;
        }
        Ok(())
    }

    /// What is reported: the effects with their parameters and intervals, the rivals, the gap per phase
    /// before and after, where what is left lies, and the augmented model.
    pub(crate) fn report(self) -> Result<Report, DiscrepancyError> {
        let (series, baseline) = (self.series, self.given);
        let base_gap = self.gap_of(baseline, 0.0)?;
        let Progress { structure, fit, named, stages, gap: final_gap, shift_se, rate_se } = &self.now;
        // A form named over its rival is reported while the model still carries it (in either relaxation
        // form).
        let mut form_rivals = vec![];
        for mut a in self.forms.iter().cloned() {
            let carried = named.iter().map(|x| x.0).find(|&f| {
                a.named.as_deref() == Some(f.id())
                    || (f == Family::QuasiLinear && a.named.as_deref() == Some(Family::Relaxation.id()))
            });
            if let Some(f) = carried {
                a.named = Some(f.id().to_string());
                a.between[0] = f.id().to_string();
                form_rivals.push(a);
            }
        }
        let remaining = if !self.ambiguous.is_empty() {
            Remaining::Ambiguous
        } else if self.at_floor(final_gap) {
            Remaining::None
        } else {
            Remaining::Unexplained
        };
        let duration = series.t.last().copied().unwrap_or(0.0) - series.t.first().copied().unwrap_or(0.0);
        let effects = named
            .iter()
            .zip(stages)
            .map(|(&(f, sh), &(before, after))| {
                let parameters = parameters(&self.model, f, sh);
                let uncertainty = uncertainty(&self.data, structure, fit, f, sh, *rate_se);
                let not_identifiable = not_identifiable(&parameters, &uncertainty, duration, f, structure);
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
            .map(|(&p, &before)| (p, PhaseRms { rms_before: before, rms_after: final_gap.phases[&p] }))
            .collect();
        let residual = |m: &ContactModel, shift: f64| -> Result<Vec<f64>, DiscrepancyError> {
            Ok(simulate(m, &series.shifted(shift))?.iter().zip(&series.f).map(|(p, f)| f - p).collect())
        };
        let (refit_shift, shift) = (self.refit.contact_shift, structure.shift);
        // The lag is read against the law as given, or, where its kind was re-chosen, against the law of
        // the kind chosen (the given one's wrong damping form would read as a lag).
        let given = if self.law.kind == baseline.kind {
            simulate(baseline, series)?
        } else {
            simulate(&self.law, &series.shifted(refit_shift))?
        };
        let mut located = locate(
            series,
            &self.surface.phases,
            &given,
            &residual(&self.refit_model, refit_shift)?,
            &residual(&self.model, shift)?,
        );
        if let Some(w) = &series.wrench {
            let before = predict_wrench(&self.refit_model, &series.shifted(refit_shift), w)?;
            let after = predict_wrench(&self.model, &series.shifted(shift), w)?;
            located.channels = wrench::channels(series, &self.surface.phases, w, &before, &after);
        }
        Ok(Report {
            baseline: Baseline { kind: baseline.kind, rms: base_gap.rms },
            refit: self.refit.clone(),
            noise_floor: self.surface.sigma,
            noise_source: self.surface.noise.source,
            level_noise: self.surface.noise.level_sigma,
            effects,
            ambiguous: self.ambiguous.iter().cloned().chain(form_rivals).collect(),
            phases: phases_out,
            final_rms: final_gap.rms,
            locate: located,
            contact_shift: shift,
            contact_shift_ci: 1.96 * shift_se,
            contact_shift_identifiable: crate::shift_identifiable(series, 1.96 * shift_se),
            remaining,
            model: self.model.clone(),
            velocity_threshold: self.velocity_threshold,
            final_lag1: final_gap.lag1,
            kept_baseline: self.kept_baseline,
            bounds: self.bounds.clone(),
            law_rechosen: None,
        })
    }
}

/// How a round ended.
enum Round {
    Named,
    NothingNamed,
    /// Rivals that name nothing: the rounds stop.
    Ambiguous,
}

/// The law's k, λ and the surface position refitted on `data` (the position's column stays in every
/// later fit), then the samples re-masked where the refitted law clamps at zero, and refitted once more:
/// the structure, the surface position's standard error and the fit.
pub(crate) fn refit_law(data: &Data, law: &ContactModel) -> Result<(Structure, f64, Fit), DiscrepancyError> {
    let ex = law.exponents;
    let start = Structure {
        a: ex.a,
        b: ex.b,
        c: ex.c,
        shift: 0.0,
        offset_rate: 0.0,
        delay: 0.0,
        terms: vec![Term::Shift],
        crosstalk_both_axes: data.second_axis.is_some(),
        clamped: data.clamped.clone(),
    };
    let (mut structure, _, _) = refine_surface(data, &start);
    let first = to_model(law, data, &structure, &fit::fit(data, &structure), &[]);
    structure.clamped = clamp_mask(&first, &data.s.shifted(structure.shift))?;
    let (structure, shift_se, _) = refine_surface(data, &structure);
    let fit = fit::fit(data, &structure);
    Ok((structure, shift_se, fit))
}

/// The phases, noise floor and free samples with the surface moved by `shift`.
fn at_surface(series: &Series, options: &Options, velocity_threshold: f64, force_scale: f64, shift: f64) -> AtSurface {
    let shifted = series.shifted(shift);
    let phases = phases(&shifted, velocity_threshold);
    let noise = noise_floor(&shifted, &phases, options.tare_window);
    let free: Vec<usize> = (0..series.len()).filter(|&i| !phases[i].in_contact()).collect();
    let sigma = noise.sigma.max(1e-9 * force_scale).max(1e-300);
    AtSurface { phases, noise, free, sigma }
}

/// The parameters of a named effect the record does not pin down: an interval wider than the value, not
/// finite, or a time longer than the record; and of crosstalk, the parts of the sensor's small rotation
/// the normal reading cannot show: never the turn about the normal, and one tilt where the load has one
/// axis.
fn not_identifiable(
    parameters: &std::collections::BTreeMap<String, f64>,
    uncertainty: &std::collections::BTreeMap<String, f64>,
    duration: f64,
    f: Family,
    structure: &Structure,
) -> Vec<String> {
    let mut out: Vec<String> = parameters
        .iter()
        .filter(|(k, v)| {
            uncertainty.get(*k).is_some_and(|u| !u.is_finite() || *u > v.abs() || (k.ends_with("_s") && *u > duration))
        })
        .map(|(k, _)| k.clone())
        .collect();
    if f == Family::Crosstalk {
        out.push("rotation_about_the_normal".into());
        if !structure.crosstalk_both_axes {
            out.push("coupling_across_the_lateral_axis".into());
        }
    }
    out
}
