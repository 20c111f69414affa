//! What the workflow reports: the named effects, what remains, and where the gap is.

use super::*;

/// What is left after the workflow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Remaining {
    /// The residual is at the noise floor.
    None,
    /// A structured residual that no candidate explains.
    Unexplained,
    /// Two candidates explain the same residual; the recording cannot tell them apart.
    Ambiguous,
}

/// The baseline as given.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Baseline {
    pub kind: Kind,
    /// In-contact residual RMS of the baseline as given \[N\].
    pub rms: f64,
}

/// The baseline's k and λ refitted on this recording (exponents fixed), before any effect; of the kind
/// the workflow re-chose where it did ([`Report::law_rechosen`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Refit {
    pub kind: Kind,
    pub stiffness: f64,
    pub damping: f64,
    /// The surface position refitted along the normal \[m\] (positive: deeper than the given one), and the
    /// half-width of its 95 % interval.
    pub contact_shift: f64,
    pub contact_shift_ci: f64,
    /// The interval is finite and within the record's own span of depth ([`shift_identifiable`]).
    pub contact_shift_identifiable: bool,
    pub rms: f64,
}

/// A surface position the record pins down: its 95 % half-width `ci` is finite and no wider than the span
/// of depth the record travels (a wider one places the surface anywhere the record could tell).
pub fn shift_identifiable(series: &crate::Series, ci: f64) -> bool {
    let (lo, hi) = series.z.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &z| (a.min(z), b.max(z)));
    ci.is_finite() && ci <= hi - lo
}

/// A named effect with its SI parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NamedEffect {
    pub id: String,
    /// NAME_SI_UNIT → value, from the final joint fit.
    pub parameters: BTreeMap<String, f64>,
    /// NAME_SI_UNIT → half-width of the 95 % interval (autocorrelation-inflated).
    pub uncertainty: BTreeMap<String, f64>,
    /// The parameters the record does not identify: an interval wider than the value itself (its sign
    /// unknown) or, for a time, than the record's own duration. Reported, not read as values.
    pub not_identifiable: Vec<String>,
    /// In-contact RMS before and after this effect was added \[N\].
    pub rms_before: f64,
    pub rms_after: f64,
}

/// Two candidates the recording cannot tell apart.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ambiguity {
    pub between: [String; 2],
    pub would_separate: String,
    /// Where both are forms of the surface's own dissipation (a loop that a relaxation and a hysteresis
    /// both close), the loop is a finding and its form is not: the one that predicts held-out data best
    /// is named and carried in the model, the other reported here. `None`: nothing of the two is named.
    pub named: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PhaseRms {
    pub rms_before: f64,
    pub rms_after: f64,
}

/// In-contact samples in one range of a quantity, and the residual RMS there.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bin {
    pub from: f64,
    pub to: f64,
    pub samples: usize,
    pub rms_before: f64,
    pub rms_after: f64,
}

/// Where the gap is (before: the refitted baseline; after: the augmented model).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Locate {
    /// Quartiles of the in-contact samples by |ż| [m/s] and by measured force \[N\].
    pub by_speed: Vec<Bin>,
    pub by_force: Vec<Bin>,
    /// Lag-1 autocorrelation of the in-contact residual (≈ 0 when white).
    pub whiteness_before: f64,
    pub whiteness_after: f64,
    /// The lag \[s\] within ±0.2 s at which the measured force's rate correlates best with the given
    /// baseline's predicted rate, and that correlation: a force that lags the motion by d peaks at +d (to a
    /// sample; smooth motions make the peak broad).
    pub lag_s: f64,
    pub lag_correlation: f64,
    /// The residual of every wrench channel, when the series carries the wrench ([`Series::with_wrench`]).
    pub channels: Vec<Channel>,
    /// The phase holding the largest share of what is left (the augmented model's squared residual over
    /// every sample, free ones included: a pull past the surface shows there).
    pub largest: Option<Largest>,
}

/// Where most of the remaining residual (measured − model) is, and its shape there.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Largest {
    pub phase: Phase,
    /// This phase's share of the whole record's squared residual.
    pub share: f64,
    pub rms: f64,
    /// The mean: near ±rms an offset (the measured force above or below the model throughout the phase),
    /// near 0 a wave about the model.
    pub mean: f64,
    /// The time [s, the record's clock] by which half of this phase's squared residual has passed.
    pub around_s: f64,
}

/// Quartile bins of `key` over the in-contact samples; a bin between equal quartiles (a quarter of the
/// samples at rest, say) holds none and is left out.
pub(crate) fn bins(key: &[f64], contact: &[usize], before: &[f64], after: &[f64]) -> Vec<Bin> {
    let mut sorted: Vec<f64> = contact.iter().map(|&i| key[i]).collect();
    if sorted.is_empty() {
        return vec![];
    }
    sorted.sort_by(f64::total_cmp);
    let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
    let edges = [q(0.0), q(0.25), q(0.5), q(0.75), q(1.0)];
    (0..4)
        .map(|b| {
            let inside: Vec<usize> = contact
                .iter()
                .copied()
                .filter(|&i| key[i] >= edges[b] && (key[i] < edges[b + 1] || (b == 3 && key[i] <= edges[4])))
                .collect();
            let rms =
                |r: &[f64]| (inside.iter().map(|&i| r[i] * r[i]).sum::<f64>() / inside.len().max(1) as f64).sqrt();
            Bin {
                from: edges[b],
                to: edges[b + 1],
                samples: inside.len(),
                rms_before: rms(before),
                rms_after: rms(after),
            }
        })
        .filter(|b| b.samples > 0)
        .collect()
}

pub(crate) fn locate(series: &Series, phases: &[Phase], given: &[f64], before: &[f64], after: &[f64]) -> Locate {
    let contact: Vec<usize> = (0..series.len()).filter(|&i| phases[i].in_contact()).collect();
    let speed: Vec<f64> = series.zdot.iter().map(|v| v.abs()).collect();
    let contact = &contact[..];
    let lag1 = |r: &[f64]| {
        let (mut lag, mut ss) = (0.0, 0.0);
        for &i in contact {
            ss += r[i] * r[i];
            if i > 0 && phases[i - 1].in_contact() {
                lag += r[i] * r[i - 1];
            }
        }
        if ss > 0.0 { lag / ss } else { 0.0 }
    };
    // Cross-correlation of the measured force's rate with the given baseline's (not the refitted one: its
    // damping absorbs part of a lag), in contact, over ±0.2 s: a sensor or a stamp that lags the motion by
    // d peaks at +d.
    let mut dts: Vec<f64> = series.t.windows(2).map(|w| w[1] - w[0]).collect();
    dts.sort_by(f64::total_cmp);
    let dt = dts.get(dts.len() / 2).copied().unwrap_or(1.0).max(1e-6);
    // On a grid of at least 5 ms (the lag's resolution; a 1 kHz recording's cost stays small), first
    // differences (a hold's level would otherwise swamp the timing), in contact only.
    let step = ((0.005 / dt).round() as usize).max(1);
    let dt = dt * step as f64;
    let reach = ((0.2 / dt).round() as usize).clamp(1, 200);
    let grid: Vec<usize> = (step..series.len()).step_by(step).collect();
    let rate = |v: &[f64]| -> Vec<f64> {
        grid.iter()
            .map(|&i| if phases[i].in_contact() && phases[i - step].in_contact() { v[i] - v[i - step] } else { 0.0 })
            .collect()
    };
    let (fc, pc) = (rate(&series.f), rate(given));
    let norm = (fc.iter().map(|x| x * x).sum::<f64>() * pc.iter().map(|x| x * x).sum::<f64>()).sqrt().max(1e-300);
    let corr: Vec<f64> = (0..=2 * reach)
        .map(|k| {
            let k = k as isize - reach as isize;
            (0..fc.len() as isize)
                .filter(|&i| i - k >= 0 && ((i - k) as usize) < fc.len())
                .map(|i| fc[i as usize] * pc[(i - k) as usize])
                .sum::<f64>()
                / norm
        })
        .collect();
    let best = (0..corr.len()).max_by(|&a, &b| corr[a].total_cmp(&corr[b])).unwrap_or(reach);
    let (lag_s, lag_correlation) = ((best as f64 - reach as f64) * dt, corr[best]);
    let total: f64 = after.iter().map(|r| r * r).sum();
    let largest = Phase::ALL
        .into_iter()
        .filter_map(|phase| {
            let inside: Vec<usize> = (0..after.len()).filter(|&i| phases[i] == phase).collect();
            let ss: f64 = inside.iter().map(|&i| after[i] * after[i]).sum();
            let n = inside.len() as f64;
            let mut passed = 0.0;
            let half = inside.iter().find(|&&i| {
                passed += after[i] * after[i];
                passed >= 0.5 * ss
            });
            (n > 0.0 && total > 0.0).then(|| Largest {
                phase,
                share: ss / total,
                rms: (ss / n).sqrt(),
                mean: inside.iter().map(|&i| after[i]).sum::<f64>() / n,
                around_s: half.map_or(series.t[0], |&i| series.t[i]),
            })
        })
        .max_by(|a, b| a.share.total_cmp(&b.share));
    Locate {
        by_speed: bins(&speed, contact, before, after),
        by_force: bins(&series.f, contact, before, after),
        whiteness_before: lag1(before),
        whiteness_after: lag1(after),
        lag_s,
        lag_correlation,
        channels: Vec::new(),
        largest,
    }
}

/// The result of [`analyse`]; serialises to the design's discrepancy JSON (without `model_file`, which the
/// CLI adds), with `refit` and `noise_source` besides.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub baseline: Baseline,
    pub refit: Refit,
    pub noise_floor: f64,
    pub noise_source: NoiseSource,
    /// [`NoiseFloor::level_sigma`]: a slow offset smaller than [`Options::level_margin`] times this is not
    /// named.
    pub level_noise: f64,
    pub effects: Vec<NamedEffect>,
    pub ambiguous: Vec<Ambiguity>,
    /// Per phase (only phases with samples): RMS of the baseline as given and of the final model. Out of
    /// contact (`free`, `approach`) the RMS is over that phase's own samples.
    pub phases: BTreeMap<Phase, PhaseRms>,
    pub final_rms: f64,
    /// Where the gap is: by speed and force level, whiteness, lag against the motion.
    pub locate: Locate,
    /// The surface position of the augmented model, along the normal from the given one \[m\]; re-simulate
    /// the recording with `series.shifted(contact_shift)`.
    pub contact_shift: f64,
    pub contact_shift_ci: f64,
    /// As [`Refit::contact_shift_identifiable`].
    pub contact_shift_identifiable: bool,
    pub remaining: Remaining,
    /// The augmented model (the baseline refitted when nothing was named).
    #[serde(skip)]
    pub model: ContactModel,
    #[serde(skip)]
    pub velocity_threshold: f64,
    /// Lag-1 autocorrelation of the final in-contact residual (≈ 0 when white).
    #[serde(skip)]
    pub final_lag1: f64,
    /// The refitted or augmented model fitted the record worse than the baseline as given, so the
    /// baseline is the result (`model`) and nothing is named.
    pub kept_baseline: bool,
    /// Effects whose shape ended at an end of the range screened: bounds, not findings, not named.
    pub bounds: Vec<Bound>,
    /// Where the given law's kind was wrong and another kind's, refitted, fitted the record better before
    /// any effect and after the whole workflow (`law.rs`): which, and by how much. Everything else in
    /// the report is then the analysis on that kind's law.
    pub law_rechosen: Option<LawChoice>,
}

/// The base law's kind re-chosen: from the given kind to another, with the held-out RMS of each refitted
/// law before any effect and the RMS over the whole record of each one's final model \[N\].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LawChoice {
    pub from: Kind,
    pub to: Kind,
    pub held_out_rms_from: f64,
    pub held_out_rms_to: f64,
    pub final_rms_from: f64,
    pub final_rms_to: f64,
}

/// An effect whose shape (a time constant, a hysteresis scale, a delay, an exponent) ended at an end of
/// the range it was screened on: the record says only that it is beyond, so it is not named.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bound {
    pub id: String,
    pub shape: f64,
    pub range: (f64, f64),
}
