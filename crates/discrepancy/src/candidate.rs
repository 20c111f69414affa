//! A candidate effect fitted and judged: its t, fold stability and physics, the screen over its shape
//! grid, and the rules it must pass beside the white-noise gates.

use super::*;
use crate::golden::golden;

/// A fitted candidate option (one family, or a pair).
#[derive(Clone)]
pub(crate) struct Cand {
    pub(crate) fams: Vec<(Family, f64)>,
    pub(crate) st: Structure,
    pub(crate) fit: Fit,
    pub(crate) t: Vec<f64>,
    pub(crate) stable: Vec<bool>,
    pub(crate) physical: bool,
}

pub(crate) fn term_index(st: &Structure, fam: Family, shape: f64) -> Option<usize> {
    let t = fam.term(shape)?;
    st.terms.iter().position(|x| *x == t).map(|i| i + 2)
}

/// Fits the option and computes each new member's t and fold stability.
pub(crate) fn assess(d: &Data, cur: &Structure, fams: &[(Family, f64)], scales: &Scales) -> Cand {
    let v_sat = scales.saturating_speed;
    let st = fams.iter().fold(cur.clone(), |s, &(f, sh)| f.apply(&s, sh));
    let fit = fit::fit(d, &st);
    let k = fit.beta[0];
    // k > 0, and no negative damping beyond its noise: a refit λ < 0 is the signature of a lag the
    // candidate (a fast relaxation branch, say) would only be covering for, and the model clamps λ at 0.
    let mut physical = k > 0.0 && fit.beta[1] >= -2.0 * fit.se[1];
    let mut t = Vec::new();
    let mut stable = Vec::new();
    for &(f, sh) in fams {
        if let Some(j) = term_index(&st, f, sh) {
            // Crosstalk along two axes is judged by the coupling the record shows best.
            let t_of = |j: usize| (fit.beta[j] / fit.se[j]).abs();
            let j = match st.terms.iter().position(|t| *t == Term::CrosstalkSecond) {
                Some(k) if f == Family::Crosstalk && t_of(k + 2) > t_of(j) => k + 2,
                _ => j,
            };
            let b = fit.beta[j];
            t.push(b / fit.se[j]);
            stable.push(fit.fold_beta.iter().all(|fb| fb[j].signum() == b.signum()));
            match f {
                Family::Relaxation | Family::QuasiLinear => physical &= b > 0.0,
                // A loop whose velocity scale is above the speeds reached never saturates: there it is a
                // damping ∝ the elastic force, the proxy of a rate law the baseline lacks, not hysteresis.
                Family::Hysteresis => physical &= b > 0.0 && b / k < 1.0 && sh <= v_sat,
                // A small mixing of channels, a plausible tool: larger ones are something else.
                Family::Crosstalk => physical &= b.abs() < 0.3,
                Family::ToolGravity => physical &= b.abs() <= 100.0,
                // A sensor offset beyond a plausible one (`MAX_SENSOR_BIAS`, `MAX_SENSOR_DRIFT`: a warming
                // F/T sensor drifts mN/s) is something else that the record shows as a slow trend.
                Family::SensorBias => physical &= b.abs() <= softcontact_contact::MAX_SENSOR_BIAS,
                Family::SensorDrift => physical &= b.abs() <= softcontact_contact::MAX_SENSOR_DRIFT,
                // Its letting go seen: the hand goes past the range after a contact at least once.
                Family::Adhesion => physical &= b > 0.0 && let_go_steps(d, &st, j).next().is_some(),
                // A medium resists the motion; a plausible one (`MAX_MEDIUM_DRAG`).
                Family::MediumDrag | Family::SqueezeFilm => {
                    physical &= b > 0.0 && b <= softcontact_contact::MAX_MEDIUM_DRAG
                }
                _ => {}
            }
        } else if f == Family::TimeDelay {
            // The delay: t from the linearised column −ṗ at the fitted delay (its coefficient is δ, the
            // delay's change); fold stability from the same test at no delay with the other members.
            let linear = |s: &Structure| {
                let base = fit::fit(d, s);
                let mut cols = fit::columns(d, s);
                cols.push(fit::negative_rate(&d.time, &base.pred).into());
                fit::fit_columns(d, &cols)
            };
            let fd = linear(&st);
            t.push(sh / fd.se[fd.se.len() - 1]);
            let mut lin = fams.iter().filter(|x| x.0 != f).fold(cur.clone(), |s, &(g, gs)| g.apply(&s, gs));
            lin.delay = cur.delay;
            let fl = linear(&lin);
            let j = fl.beta.len() - 1;
            stable.push(fl.fold_beta.iter().all(|fb| fb[j] > 0.0));
            // An optimum at the grid's lower end is a lag at most that long: the nominal chain's.
            physical &= Scales::inside(sh, scales.delays);
        } else {
            // The exponent: t from the linearised column zᵃ′·ln z at the fitted a′ (its coefficient is k·δa);
            // fold stability from the linear test at the current a with the other members.
            let mut sd = st.clone();
            sd.terms.push(Term::ExpDeriv);
            let fd = fit::fit(d, &sd);
            let se_a = fd.se[fd.se.len() - 1] / fd.beta[0].abs().max(1e-300);
            let delta = sh - cur.a;
            t.push(delta / se_a);
            let mut lin = fams.iter().filter(|x| x.0 != f).fold(cur.clone(), |s, &(g, gs)| g.apply(&s, gs));
            lin.terms.push(Term::ExpDeriv);
            let fl = fit::fit(d, &lin);
            let j = fl.beta.len() - 1;
            stable.push(fl.fold_beta.iter().all(|fb| fb[j].signum() == delta.signum()));
        }
    }
    Cand { fams: fams.to_vec(), st, fit, t, stable, physical }
}

/// The best shape of a family by held-out MSE on the grid, refined by golden section on the in-sample SSE
/// between the grid neighbours.
/// A family whose best grid point does not beat `cv_now` (the current model's held-out MSE) is neither
/// refined nor tested: it cannot pass.
pub(crate) fn screen(d: &Data, cur: &Structure, fam: Family, scales: &Scales, cv_now: f64) -> Cand {
    let grid = fam.grid(scales, cur);
    let scores: Vec<f64> = grid.iter().map(|&sh| fit::held_out_mse(d, &fam.apply(cur, sh))).collect();
    let best = (0..grid.len()).min_by(|&i, &j| scores[i].total_cmp(&scores[j])).unwrap_or(0);
    let mut shape = grid[best];
    if scores[best] >= cv_now {
        // Hopeless: no t or fold stability needed (nor can it be a rival: it gains nothing).
        let st = fam.apply(cur, shape);
        let fit = fit::fit(d, &st);
        return Cand { fams: vec![(fam, shape)], st, fit, t: vec![0.0], stable: vec![false], physical: false };
    }
    if fam.has_shape() && grid.len() > 2 {
        let (mut lo, mut hi) = (grid[best.saturating_sub(1)], grid[(best + 1).min(grid.len() - 1)]);
        // The grid leaves out time constants within 3× of a branch already there; so does the refinement.
        for t in &cur.terms {
            if let Term::Relax(other) = *t
                && fam == Family::Relaxation
            {
                if other < shape { lo = lo.max(3.0 * other) } else { hi = hi.min(other / 3.0) }
            }
        }
        let logscale = fam != Family::StiffnessExponent;
        type Map = fn(f64) -> f64;
        let (tx, fx): (Map, Map) = if logscale { (f64::ln, f64::exp) } else { (|x| x, |x| x) };
        let sh = golden(|x| fit::fit(d, &fam.apply(cur, fx(x))).sse, tx(lo), tx(hi), 14);
        shape = fx(sh);
        if fam == Family::StiffnessExponent && (shape - cur.a).abs() < 1e-3 {
            shape = grid[best];
        }
    }
    assess(d, cur, &[(fam, shape)], scales)
}

/// Whether every slow offset among the candidate's members moves the force somewhere by more than
/// `level`: a tare's own reading leaves an offset of the noise averaged over its window, and a slow noise
/// moves the level as much; neither is an effect. A bias is its own size and a sensor drift its size since
/// the tare (both zero at the tare); a drifting surface zero half its force's range (the surface position,
/// refitted with it, takes its mean), named only where the free stretches' levels agree within `level`: a
/// sensor whose offset wanders further moves the force in contact as much, and the recording cannot tell
/// the two apart. An adhesion is its pull-off force: a pull for a moment past the surface is what a slow
/// noise can look like there.
pub(crate) fn slow_offsets_material(d: &Data, c: &Cand, level: f64, stretches: &[&[usize]]) -> bool {
    let slow =
        |f: Family| matches!(f, Family::SensorBias | Family::SensorDrift | Family::OffsetDrift | Family::Adhesion);
    if !c.fams.iter().any(|&(f, _)| slow(f)) {
        return true;
    }
    let cols = fit::columns(d, &c.st);
    let free_levels =
        stretches.iter().map(|run| run.iter().map(|&i| d.s.f[i] - c.fit.pred[i]).sum::<f64>() / run.len() as f64);
    let (lo, hi) = free_levels.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| (lo.min(x), hi.max(x)));
    let free_spread = if hi >= lo { hi - lo } else { 0.0 };
    c.fams.iter().filter(|&&(f, _)| slow(f)).all(|&(f, sh)| {
        term_index(&c.st, f, sh).is_some_and(|j| {
            let force = cols[j].iter().filter(|x| **x != 0.0).map(|x| c.fit.beta[j] * x);
            let (lo, hi) = force.fold((0.0f64, 0.0f64), |(lo, hi), x| (lo.min(x), hi.max(x)));
            let size = if f == Family::OffsetDrift { (hi - lo) / 2.0 } else { hi.max(-lo) };
            size > level && (f != Family::OffsetDrift || free_spread <= level)
        })
    })
}

/// The phase-local rule (see the crate's README): where the residual is dominated by what no effect of
/// the library describes (an adhesion pulling while still indented, a controller's own loop), a true
/// effect closes the phase where it acts and is judged there. The candidate passes when, on held-out
/// predictions, (1) the in-contact MSE falls by [`Options::min_gain`]; (2) in some in-contact phase with
/// [`LOCAL_MIN_SHARE`] of the contact samples and a residual well above the noise (MSE ≥ 4 σ²), it
/// removes [`LOCAL_SHARE`] of the excess over σ²; and (3) it makes no in-contact phase worse by more than
/// [`LOCAL_WORSE`].
pub(crate) fn phase_local(ph: &[Phase], before: &[f64], after: &[f64], sigma: f64, o: &Options) -> bool {
    let mut sums: BTreeMap<Phase, (f64, f64, usize)> = BTreeMap::new();
    for i in (0..ph.len()).filter(|&i| ph[i].in_contact()) {
        let e = sums.entry(ph[i]).or_default();
        e.0 += before[i];
        e.1 += after[i];
        e.2 += 1;
    }
    let contact: usize = sums.values().map(|v| v.2).sum();
    let (b, a): (f64, f64) = sums.values().fold((0.0, 0.0), |acc, v| (acc.0 + v.0, acc.1 + v.1));
    if contact == 0 || a > b * (1.0 - o.min_gain) {
        return false;
    }
    let s2 = sigma * sigma;
    let worse = sums.values().any(|v| v.1 > v.0 * (1.0 + LOCAL_WORSE));
    let closes = sums.values().any(|v| {
        let n = v.2 as f64;
        let (mb, ma) = (v.0 / n, v.1 / n);
        n >= LOCAL_MIN_SHARE * contact as f64 && mb >= 4.0 * s2 && mb - ma >= LOCAL_SHARE * (mb - s2)
    });
    closes && !worse
}

/// The phase-local rule's share of the excess removed in the phase where the effect acts...
pub const LOCAL_SHARE: f64 = 0.5;
/// ...in a phase holding at least this share of the in-contact samples...
pub const LOCAL_MIN_SHARE: f64 = 0.1;
/// ...while no in-contact phase's held-out MSE grows by more than this share.
pub const LOCAL_WORSE: f64 = 0.1;

pub(crate) fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for i in 0..a.len() {
        sab += (a[i] - ma) * (b[i] - mb);
        saa += (a[i] - ma).powi(2);
        sbb += (b[i] - mb).powi(2);
    }
    if saa > 0.0 && sbb > 0.0 { sab / (saa * sbb).sqrt() } else { 0.0 }
}
