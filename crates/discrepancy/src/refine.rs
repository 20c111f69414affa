//! The shapes of the named effects refined together (τ, v₀, a′, delay, range).

use super::*;
use crate::golden::golden;

/// Polish: each shape (τ of a relaxation branch, v₀ of the hysteresis) was chosen in its own round, with
/// the effects of that round, and the shapes trade against each other and against the damping (a fast
/// branch and a hysteresis both stiffen fast pushes). Refine them jointly in the current structure by
/// Gauss–Newton on their logarithms — each shape's column differentiated numerically, the change of its
/// shape read from a joint fit as the surface position's is (variable projection) — within their bounds
/// (τ in the screening grid's range with branches 3× apart, v₀ up to the saturating speed), halving a step
/// that does not lower the in-sample error. With `regrid`, each shape is first re-chosen on its grid. True if
/// any shape moved.
pub(crate) fn polish(
    d: &Data,
    st: &mut Structure,
    cur: &mut Fit,
    order: &mut [(Family, f64)],
    scales: &Scales,
    regrid: bool,
) -> bool {
    let shaped: Vec<usize> = (0..st.terms.len()).filter(|&j| shape_of(st.terms[j]).is_some()).collect();
    if shaped.is_empty() {
        return false;
    }
    let (start, start_sse) = (st.terms.clone(), cur.sse);
    if regrid {
        regrid_shapes(d, st, cur, &shaped, scales);
    }
    gauss_newton_shapes(d, st, cur, &shaped, scales, if regrid { POLISH_ITERATIONS } else { POLISH_ITERATIONS / 2 });
    search_adhesion_ranges(d, st, cur, &shaped, scales);
    if cur.sse >= start_sse {
        return false;
    }
    *st = refine_surface(d, st).0;
    *cur = fit::fit(d, st);
    for &j in &shaped {
        let (Some((fam, before)), Some((_, after))) = (shape_of(start[j]), shape_of(st.terms[j])) else { continue };
        if let Some(slot) = order.iter_mut().find(|x| x.0 == fam && x.1 == before) {
            slot.1 = after;
        }
    }
    true
}

/// The structure with `set`'s terms in place, kept where it lowers the in-sample error.
fn try_terms(d: &Data, st: &mut Structure, cur: &mut Fit, set: &[(usize, Term)]) {
    let mut trial = st.clone();
    for &(j, t) in set {
        trial.terms[j] = t;
    }
    let ft = fit::fit(d, &trial);
    if ft.sse < cur.sse {
        *st = trial;
        *cur = ft;
    }
}

/// The shapes re-chosen on their grids, the others held — two relaxation branches as a pair: a branch
/// chosen early (between two time scales, before the second branch was in) sits in a basin that
/// Gauss–Newton does not leave.
fn regrid_shapes(d: &Data, st: &mut Structure, cur: &mut Fit, shaped: &[usize], scales: &Scales) {
    let relaxation: Vec<usize> = shaped.iter().copied().filter(|&j| matches!(st.terms[j], Term::Relax(_))).collect();
    if let &[i, j] = &relaxation[..] {
        // The faster branch stays the faster (its slot in `order` keeps its round).
        let tau = |k: usize| if let Term::Relax(x) = st.terms[k] { x } else { 0.0 };
        let (i, j) = if tau(i) < tau(j) { (i, j) } else { (j, i) };
        let mut without = st.clone();
        without.terms.retain(|t| !matches!(t, Term::Relax(_)));
        let grid = Family::Relaxation.grid(scales, &without);
        for (m, &a) in grid.iter().enumerate() {
            for &b in grid[m + 1..].iter().filter(|&&b| b >= 3.0 * a) {
                try_terms(d, st, cur, &[(i, Term::Relax(a)), (j, Term::Relax(b))]);
            }
        }
    }
    for &j in shaped {
        let Some((fam, _)) = shape_of(st.terms[j]) else { continue };
        let mut without = st.clone();
        without.terms.remove(j);
        let grid = fam.grid(scales, &without);
        for x in grid.into_iter().filter(|&x| fam != Family::Hysteresis || x <= scales.saturating_speed) {
            try_terms(d, st, cur, &[(j, fam.term(x).unwrap_or(st.terms[j]))]);
        }
    }
}

/// The term with its shape multiplied by `factor`.
fn scaled(t: Term, factor: f64) -> Term {
    match shape_of(t) {
        Some((fam, x)) => fam.term(x * factor).unwrap_or(t),
        None => t,
    }
}

/// Every shape within its bounds: τ in the screening grid's range with branches 3× apart, v₀ up to the
/// saturating speed, an adhesion's range in its range.
fn within_bounds(s: &Structure, scales: &Scales) -> bool {
    let taus: Vec<f64> =
        s.terms.iter().filter_map(|t| if let Term::Relax(tau) = *t { Some(tau) } else { None }).collect();
    s.terms.iter().all(|t| match *t {
        Term::Relax(tau) => (scales.time_constants.0..=scales.time_constants.1).contains(&tau),
        Term::Hyst(v0) => v0 > 0.0 && v0 <= scales.saturating_speed,
        Term::Adhesion(range) => (scales.adhesion_ranges.0..=scales.adhesion_ranges.1).contains(&range),
        Term::QuasiRelax(tau) => (scales.time_constants.0..=scales.time_constants.1).contains(&tau),
        Term::Squeeze(reach) => (scales.squeeze_reaches.0..=scales.squeeze_reaches.1).contains(&reach),
        _ => true,
    }) && taus.iter().enumerate().all(|(i, a)| taus[i + 1..].iter().all(|b| (a / b).ln().abs() >= 3f64.ln()))
}

/// Gauss–Newton on the shapes' logarithms, each shape's column differentiated numerically and the change
/// of its shape read from a joint fit (variable projection), a step that does not lower the in-sample error
/// halved, at most `iterations` steps.
fn gauss_newton_shapes(
    d: &Data,
    st: &mut Structure,
    cur: &mut Fit,
    shaped: &[usize],
    scales: &Scales,
    iterations: usize,
) {
    const H: f64 = 1e-3;
    for _ in 0..iterations {
        let mut cols = fit::columns(d, st);
        let p = cols.len();
        for &j in shaped {
            let mut up = st.clone();
            up.terms[j] = scaled(st.terms[j], H.exp());
            let moved = fit::columns(d, &up).swap_remove(j + 2);
            cols.push(moved.iter().zip(cols[j + 2].iter()).map(|(u, c)| (u - c) / H).collect());
        }
        let linear = fit::fit_columns(d, &cols);
        let mut step: Vec<f64> = shaped
            .iter()
            .enumerate()
            .map(|(m, &j)| (linear.beta[p + m] / linear.beta[j + 2]).clamp(-2f64.ln(), 2f64.ln()))
            .collect();
        let mut improved = false;
        for _ in 0..5 {
            let mut trial = st.clone();
            for (m, &j) in shaped.iter().enumerate() {
                trial.terms[j] = scaled(st.terms[j], step[m].exp());
            }
            // The surface position's column stays in the fit: it is moved into the structure once, after.
            if step.iter().all(|x| x.is_finite()) && within_bounds(&trial, scales) {
                let ft = fit::fit(d, &trial);
                if ft.sse < cur.sse {
                    *st = trial;
                    *cur = ft;
                    improved = true;
                    break;
                }
            }
            step.iter_mut().for_each(|x| *x *= 0.5);
        }
        if !improved || step.iter().all(|x| x.abs() < 1e-4) {
            break;
        }
    }
}

/// Where an adhesion lets go is a step of its column: Gauss–Newton sees only its smooth part, so its range
/// gets a golden-section search of its own, the other shapes held.
fn search_adhesion_ranges(d: &Data, st: &mut Structure, cur: &mut Fit, shaped: &[usize], scales: &Scales) {
    for &j in shaped {
        let Term::Adhesion(range) = st.terms[j] else { continue };
        let (lo, hi) = (scales.adhesion_ranges.0.max(range / 2.0), scales.adhesion_ranges.1.min(range * 2.0));
        if lo < hi {
            // At the surface each range places: where it lets go moves with it.
            let placed = |x: f64| {
                let mut trial = st.clone();
                trial.terms[j] = Term::Adhesion(x);
                refine_surface(d, &trial).0
            };
            let best = golden(|x| fit::fit(d, &placed(x.exp())).sse, lo.ln(), hi.ln(), 12).exp();
            let trial = placed(best);
            let ft = fit::fit(d, &trial);
            if ft.sse < cur.sse {
                *st = trial;
                *cur = ft;
            }
        }
    }
}

/// The family and shape of a term [`polish`] refines (a relaxation's τ, a hysteresis' v₀, an adhesion's
/// range); None for a term without a shape.
pub(crate) fn shape_of(t: Term) -> Option<(Family, f64)> {
    match t {
        Term::Relax(x) => Some((Family::Relaxation, x)),
        Term::Hyst(x) => Some((Family::Hysteresis, x)),
        Term::Adhesion(x) => Some((Family::Adhesion, x)),
        Term::QuasiRelax(x) => Some((Family::QuasiLinear, x)),
        Term::Squeeze(x) => Some((Family::SqueezeFilm, x)),
        _ => None,
    }
}

/// Gauss–Newton iterations of [`polish`] (half of them after each accepted round).
pub(crate) const POLISH_ITERATIONS: usize = 8;
