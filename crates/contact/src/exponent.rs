//! Beyond fixed exponents: the stiffness exponent a and the contact offset, each estimated by variable
//! projection — for a trial value the law is linear in (k, λ), whose least-squares solution is exact,
//! so only a one-dimensional residual has to be minimised.

use crate::ContactError;
use crate::fit::{Fit, FitConfig, Moments, Prior, Sample, fit};
use crate::model::{Exponents, Kind};

/// How the damping exponent b follows the estimated stiffness exponent a.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DampingExponent {
    /// b fixed (Azad-Featherstone-like families: b = 1/2).
    Fixed(f64),
    /// b = a + offset (Hunt-Crossley-like: offset 0).
    FollowsStiffness(f64),
}

impl DampingExponent {
    fn b(self, a: f64) -> f64 {
        match self {
            DampingExponent::Fixed(b) => b,
            DampingExponent::FollowsStiffness(offset) => a + offset,
        }
    }
}

/// Minimises a unimodal-near-the-minimum function on [lo, hi]: a grid finds the basin, golden-section
/// search narrows it to `tol`. Returns (argmin, value, evaluations).
pub fn minimize_scalar(mut f: impl FnMut(f64) -> f64, lo: f64, hi: f64, grid: usize, tol: f64) -> (f64, f64, usize) {
    let step = (hi - lo) / grid as f64;
    let values: Vec<f64> = (0..=grid).map(|i| f(lo + step * i as f64)).collect();
    let best = values
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i);
    let (mut a, mut b) = (lo + step * best.saturating_sub(1) as f64, lo + step * (best + 1).min(grid) as f64);
    let phi = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x1, mut x2) = (b - phi * (b - a), a + phi * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    let mut evaluations = grid + 3;
    while (b - a) > tol {
        if f1 <= f2 {
            b = x2;
            (x2, f2) = (x1, f1);
            x1 = b - phi * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            (x1, f1) = (x2, f2);
            x2 = a + phi * (b - a);
            f2 = f(x2);
        }
        evaluations += 1;
    }
    let (x, v) = if f1 <= f2 { (x1, f1) } else { (x2, f2) };
    if values[best] < v { (lo + step * best as f64, values[best], evaluations) } else { (x, v, evaluations) }
}

/// Residual sum of squares of the best (k, λ) for given moments (∞ when they determine nothing).
fn projected_rss(m: &Moments) -> f64 {
    match m.solve() {
        Some((k, l)) => m.sse(k, l),
        None => m.solve_stiffness(0.0).map_or(f64::INFINITY, |k| m.sse(k, 0.0)),
    }
}

/// Estimates the stiffness exponent a in [lo, hi] (damping exponent per `damping`, rate exponent c),
/// then fits the resulting general law with cross-validated fitness.
pub fn estimate_exponent(
    samples: &[Sample],
    damping: DampingExponent,
    c: f64,
    range: (f64, f64),
    cfg: &FitConfig,
) -> Result<Fit, ContactError> {
    if !(range.0 > 0.0 && range.1 > range.0 && c > 0.0) {
        return Err(ContactError::InvalidConfig("exponent range must satisfy 0 < lo < hi, and c > 0".into()));
    }
    // ln z once, and the part of the damping regressor that does not depend on a: each trial exponent
    // then costs one exp per sample. x₂ = zᵇ ż^c is either a constant column (b fixed) or x₁·z^offset·ż^c.
    let contact: Vec<(f64, f64, f64)> = samples
        .iter()
        .filter(|s| s.z > 0.0)
        .map(|s| {
            let rate = s.zdot.signum() * s.zdot.abs().powf(c);
            let damping_part = match damping {
                DampingExponent::Fixed(b) => s.z.powf(b) * rate,
                DampingExponent::FollowsStiffness(offset) => s.z.powf(offset) * rate,
            };
            (s.z.ln(), damping_part, s.f)
        })
        .collect();
    let outside = samples.iter().filter(|s| s.z <= 0.0).fold(0.0, |acc, s| acc + s.f * s.f);
    if contact.len() < 2 * cfg.folds {
        return Err(ContactError::NotEnoughData { kind: "exponent estimation" });
    }
    let follows = matches!(damping, DampingExponent::FollowsStiffness(_));
    let rss = |a: f64| {
        let mut m = Moments::default();
        for &(ln_z, damping_part, f) in &contact {
            let x1 = (a * ln_z).exp();
            m.add(x1, if follows { x1 * damping_part } else { damping_part }, f, 1.0);
        }
        projected_rss(&m) + outside
    };
    let (a, _, _) = minimize_scalar(rss, range.0, range.1, 16, 1e-6);
    fit(Kind::General, Exponents { a, b: damping.b(a), c }, samples, None, cfg)
}

/// Estimates where the surface really is. `samples` carry z measured from a provisional contact
/// position (e.g. the 1 N onset); the law is fitted to z − δ for δ in [lo, hi], and the δ with the
/// least residual is returned with its fit. The surface then lies at d + δ·n.
pub fn estimate_contact_offset(
    samples: &[Sample],
    exponents: Exponents,
    range: (f64, f64),
    prior: Prior,
    cfg: &FitConfig,
) -> Result<(f64, Fit), ContactError> {
    if !(range.0.is_finite() && range.1.is_finite() && range.0 < range.1) {
        return Err(ContactError::InvalidConfig("offset range must satisfy lo < hi".into()));
    }
    let shifted = |delta: f64| samples.iter().map(move |s| Sample { z: s.z - delta, ..*s });
    let rss = |delta: f64| {
        let mut m = Moments::default();
        for s in shifted(delta) {
            let (x1, x2) = crate::fit::regressors(&exponents, s.z, s.zdot);
            m.add(x1, x2, s.f, 1.0);
        }
        projected_rss(&m)
    };
    let (delta, _, _) = minimize_scalar(rss, range.0, range.1, 20, 1e-9);
    let kind = Kind::CANDIDATES.into_iter().find(|k| k.exponents() == Some(exponents)).unwrap_or(Kind::General);
    let moved: Vec<Sample> = shifted(delta).collect();
    Ok((delta, fit(kind, exponents, &moved, prior, cfg)?))
}
