//! The step of [`crate::analyse`] that tries the medium the hand moves through: its drag, a squeeze film,
//! or both ([`Analysis::try_the_medium`]).

use super::*;

/// A form of the medium admitted: its families, the progress with it (without its stages) and the model.
struct MediumForm {
    fams: Vec<(Family, f64)>,
    progress: Progress,
    model: ContactModel,
}

impl Analysis<'_> {
    /// The medium, tried once the surface's own effects are named: its only evidence of its own is free
    /// space crossed at two speeds; in contact it is one more damping, and a loop of constant width between
    /// loading and unloading, which the surface's dissipation makes too. Three forms: the medium's drag
    /// alone, a squeeze film alone (its reach the best of its grid by held-out error, not at the grid's
    /// ends), and both. Each is judged by every rule a round's candidate meets and admitted where the
    /// simulated record (every sample) fits better by the gain a new effect needs, the contact no worse and
    /// the medium no more viscous than a plausible one. Of the admitted, the single with the least
    /// in-contact gap (the gap every stage reports) is taken, or both where they leave less by that gain.
    pub(crate) fn try_the_medium(&mut self) -> Result<(), DiscrepancyError> {
        if !self.ambiguous.is_empty() || !Family::MediumDrag.observable(&self.data) {
            return Ok(());
        }
        let drag = (Family::MediumDrag, 0.0);
        let mut options = vec![vec![drag]];
        for beside in [&[][..], &[drag][..]] {
            if let Some(reach) = self.best_squeeze_reach(beside) {
                options.push(beside.iter().copied().chain([(Family::SqueezeFilm, reach)]).collect());
            }
        }
        let before = whole_rms(self.series, &self.model, self.now.structure.shift)?;
        let mut admitted = vec![];
        for fams in options {
            admitted.extend(self.medium_form(fams, before)?);
        }
        // The single with the least in-contact gap, or both where they leave less by the gain.
        let gap_of = |form: &MediumForm| form.progress.gap.rms;
        let single = admitted.iter().filter(|f| f.fams.len() == 1).min_by(|a, b| gap_of(a).total_cmp(&gap_of(b)));
        let pair = admitted.iter().find(|f| f.fams.len() > 1);
        let chosen = match (single, pair) {
            (Some(s), Some(p)) if gap_of(p) < gap_of(s) * (1.0 - self.options.min_gain) => Some(p),
            (None, p) => p,
            (s, _) => s,
        };
        let Some(MediumForm { fams, progress, model }) = chosen else { return Ok(()) };
        // A pair's stages: the drag's own gap where it was admitted, then the film's.
        let drag_gap = admitted.iter().find(|f| f.fams == [drag]).map(gap_of);
        let mut progress = progress.clone();
        let first = drag_gap.filter(|_| fams.len() > 1).unwrap_or(progress.gap.rms);
        progress.stages.push((self.now.gap.rms, first));
        if fams.len() > 1 {
            progress.stages.push((first, progress.gap.rms));
        }
        (self.now, self.model) = (progress, model.clone());
        self.move_surface();
        Ok(())
    }

    /// One form of the medium added to the model, surface refined, where it passes every rule, fits the
    /// record (every sample) better than `before` by the gain a new effect needs, the contact no worse, and
    /// drags no more than a plausible medium; None otherwise.
    fn medium_form(&self, fams: Vec<(Family, f64)>, before: f64) -> Result<Option<MediumForm>, DiscrepancyError> {
        let cand = assess(&self.data, &self.now.structure, &fams, &self.scales);
        if !self.passes(&cand, &self.free_stretches(), &OnceCell::new()) {
            return Ok(None);
        }
        let (structure, shift_se, _) = refine_surface(&self.data, &cand.st);
        let fit = fit::fit(&self.data, &structure);
        let named: Vec<(Family, f64)> = self.now.named.iter().copied().chain(fams.iter().copied()).collect();
        let model = self.model_of(&structure, &fit, &named);
        model.validate()?;
        if model.medium_drag_in_contact() > softcontact_contact::MAX_MEDIUM_DRAG {
            return Ok(None);
        }
        let rms = whole_rms(self.series, &model, structure.shift)?;
        let gap = self.gap_of(&model, structure.shift)?;
        if rms > before * (1.0 - self.options.min_gain) || gap.rms > self.now.gap.rms * (1.0 + 1e-3) {
            return Ok(None);
        }
        let stages = self.now.stages.clone();
        let progress = Progress { structure, fit, named, stages, gap, shift_se, rate_se: self.now.rate_se };
        Ok(Some(MediumForm { fams, progress, model }))
    }

    /// The reach of a squeeze film, beside `beside`, that predicts held-out data best; None where that is
    /// at an end of the grid (a bound, not a finding).
    fn best_squeeze_reach(&self, beside: &[(Family, f64)]) -> Option<f64> {
        let held_out_error = |reach: f64| {
            let fams: Vec<(Family, f64)> = beside.iter().copied().chain([(Family::SqueezeFilm, reach)]).collect();
            let st = fams.iter().fold(self.now.structure.clone(), |s, &(f, sh)| f.apply(&s, sh));
            fit::held_out_mse(&self.data, &st)
        };
        let grid = Family::SqueezeFilm.grid(&self.scales, &self.now.structure);
        let (reach, _) =
            grid.into_iter().map(|reach| (reach, held_out_error(reach))).min_by(|a, b| a.1.total_cmp(&b.1))?;
        self.scales.at_edge(Family::SqueezeFilm, reach).is_none().then_some(reach)
    }
}
