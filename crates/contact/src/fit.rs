//! Least-squares identification of f = k zᵃ + λ zᵇ żᶜ with known exponents (the force-control paper's eq. 16): the model
//! is linear in (k, λ), so each fit is a 2-parameter least-squares problem. Its sufficient statistics
//! ([`Moments`]) add and subtract sample by sample, which makes the sliding window O(1) per sample and
//! k-fold cross-validation a matter of combining per-fold moments.

use faer::Mat;
use faer::linalg::solvers::SolveLstsq;

use crate::ContactError;
use crate::model::{ContactModel, Exponents, Kind, pow};

/// One observation: deformation z \[m\], rate ż [m/s], normal force f \[N\].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    pub z: f64,
    pub zdot: f64,
    pub f: f64,
}

impl Sample {
    pub fn new(z: f64, zdot: f64, f: f64) -> Result<Self, ContactError> {
        for (name, v) in [("z", z), ("ż", zdot), ("f", f)] {
            if !v.is_finite() {
                return Err(ContactError::NonFinite { name, value: v });
            }
        }
        Ok(Self { z, zdot, f })
    }
}

/// The two regressors of a law: x₁ = zᵃ, x₂ = zᵇ·sgn(ż)|ż|ᶜ; both 0 out of contact (the law predicts 0).
#[inline]
pub fn regressors(e: &Exponents, z: f64, zdot: f64) -> (f64, f64) {
    if z <= 0.0 {
        return (0.0, 0.0);
    }
    let rate = if e.c == 1.0 { zdot } else { zdot.signum() * zdot.abs().powf(e.c) };
    (pow(z, e.a), pow(z, e.b) * rate)
}

/// Weighted sufficient statistics of the 2-parameter least-squares problem f ≈ k x₁ + λ x₂.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Moments {
    pub n: f64,
    pub s11: f64,
    pub s12: f64,
    pub s22: f64,
    pub s1f: f64,
    pub s2f: f64,
    pub sf: f64,
    pub sff: f64,
}

impl Moments {
    #[inline]
    pub fn add(&mut self, x1: f64, x2: f64, f: f64, w: f64) {
        self.n += w;
        self.s11 += w * x1 * x1;
        self.s12 += w * x1 * x2;
        self.s22 += w * x2 * x2;
        self.s1f += w * x1 * f;
        self.s2f += w * x2 * f;
        self.sf += w * f;
        self.sff += w * f * f;
    }

    #[inline]
    pub fn remove(&mut self, x1: f64, x2: f64, f: f64) {
        self.add(x1, x2, f, -1.0);
    }

    pub fn plus(&self, o: &Moments) -> Moments {
        Moments {
            n: self.n + o.n,
            s11: self.s11 + o.s11,
            s12: self.s12 + o.s12,
            s22: self.s22 + o.s22,
            s1f: self.s1f + o.s1f,
            s2f: self.s2f + o.s2f,
            sf: self.sf + o.sf,
            sff: self.sff + o.sff,
        }
    }

    /// Unconstrained least squares (k, λ), or `None` when the normal matrix is singular. The 2×2 system
    /// is solved after scaling each regressor to unit norm, so its conditioning is that of the data.
    pub fn solve(&self) -> Option<(f64, f64)> {
        if !(self.s11 > 0.0 && self.s22 > 0.0) {
            return None;
        }
        let (d1, d2) = (self.s11.sqrt(), self.s22.sqrt());
        let r = self.s12 / (d1 * d2);
        let det = 1.0 - r * r;
        if det <= 1e-13 {
            return None;
        }
        let (b1, b2) = (self.s1f / d1, self.s2f / d2);
        Some(((b1 - r * b2) / det / d1, (b2 - r * b1) / det / d2))
    }

    /// k with λ held fixed.
    pub fn solve_stiffness(&self, damping: f64) -> Option<f64> {
        (self.s11 > 0.0).then(|| (self.s1f - damping * self.s12) / self.s11)
    }

    /// Residual sum of squares of (k, λ) on these samples.
    pub fn sse(&self, k: f64, l: f64) -> f64 {
        (self.sff - 2.0 * (k * self.s1f + l * self.s2f) + k * k * self.s11 + 2.0 * k * l * self.s12 + l * l * self.s22)
            .max(0.0)
    }

    /// Total sum of squares about the mean (the denominator of the force-control paper's fitness, eq. 18).
    pub fn sst(&self) -> f64 {
        if self.n > 0.0 { (self.sff - self.sf * self.sf / self.n).max(0.0) } else { 0.0 }
    }

    /// Sum of squares of the forces about a given mean.
    pub fn sst_about(&self, mean: f64) -> f64 {
        (self.sff - 2.0 * mean * self.sf + self.n * mean * mean).max(0.0)
    }

    /// Standard errors of (k, λ) of an unconstrained fit: σ̂² (XᵀX)⁻¹ with σ̂² = SSE / (n − 2).
    pub fn standard_errors(&self, k: f64, l: f64) -> (f64, f64) {
        let det = self.s11 * self.s22 - self.s12 * self.s12;
        if self.n <= 2.0 || det <= 0.0 {
            return (f64::INFINITY, f64::INFINITY);
        }
        let sigma2 = self.sse(k, l) / (self.n - 2.0);
        ((sigma2 * self.s22 / det).sqrt(), (sigma2 * self.s11 / det).sqrt())
    }

    pub fn of(samples: &[Sample], e: &Exponents) -> Moments {
        let mut m = Moments::default();
        for s in samples {
            let (x1, x2) = regressors(e, s.z, s.zdot);
            m.add(x1, x2, s.f, 1.0);
        }
        m
    }
}

/// The force-control paper's fitness (eq. 18): 1 − Σ(σ − σ̂)² / Σ(σ − σ̄)².
pub fn fitness(sse: f64, sst: f64) -> f64 {
    if sst > 0.0 { 1.0 - sse / sst } else { f64::NAN }
}

/// How an estimator fits and judges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitConfig {
    /// Folds of the cross-validation (the force-control paper: 5). Folds are contiguous blocks in time, so a fold's
    /// test samples are never the neighbours of its training samples.
    pub folds: usize,
    /// A parameter whose relative standard error exceeds this is not identified by the data: it is
    /// held at its prior instead of following the noise (the excitation guard).
    pub max_relative_error: f64,
    /// Score every fold about the mean force of all the data (σ̄ of eq. 18 taken over the whole data
    /// set) instead of the fold's own mean. For long recordings with quasi-static holds (offline
    /// identification): a hold fold has next to no spread about its own mean, and its own-mean score
    /// says nothing about the model. The sliding window of the online estimator keeps own-mean scores.
    pub score_about_overall_mean: bool,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self { folds: 5, max_relative_error: 0.25, score_about_overall_mean: false }
    }
}

/// Prior values of (k, λ), e.g. the last accepted estimate or the identification's.
pub type Prior = Option<(f64, f64)>;

/// One kind fitted to a set of samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub kind: Kind,
    pub exponents: Exponents,
    pub stiffness: f64,
    pub damping: f64,
    /// Standard errors of the unconstrained fit.
    pub stiffness_error: f64,
    pub damping_error: f64,
    /// The data did not determine the parameter: it was held at the prior.
    pub stiffness_held: bool,
    pub damping_held: bool,
    /// Cross-validated fitness (eq. 18): mean and standard deviation over folds.
    pub fitness_mean: f64,
    pub fitness_std: f64,
    /// Fitness on all samples.
    pub fitness_all: f64,
    pub samples: usize,
}

impl Fit {
    /// The contact model of this fit (a general model when the kind's exponents were replaced).
    pub fn model(&self) -> Result<ContactModel, ContactError> {
        if self.kind.exponents() == Some(self.exponents) {
            ContactModel::new(self.kind, self.stiffness, self.damping.max(0.0))
        } else {
            ContactModel::general(self.stiffness, self.damping.max(0.0), self.exponents)
        }
    }
}

/// (k, λ) from moments with the excitation guard; flags say which parameter was held.
fn guarded_solve(m: &Moments, prior: Prior, cfg: &FitConfig) -> Option<(f64, f64, bool, bool, f64, f64)> {
    let (prior_k, prior_l) = prior.unwrap_or((0.0, 0.0));
    let Some((k, l)) = m.solve() else {
        // No information about λ at all (e.g. no motion): λ at its prior, k from the data.
        let k = m.solve_stiffness(prior_l)?;
        return Some((k, prior_l, false, true, f64::INFINITY, f64::INFINITY));
    };
    let (ek, el) = m.standard_errors(k, l);
    let damping_held = el > cfg.max_relative_error * l.abs().max(prior_l.abs());
    let (k, l) = if damping_held { (m.solve_stiffness(prior_l)?, prior_l) } else { (k, l) };
    let stiffness_held = prior.is_some() && ek > cfg.max_relative_error * k.abs().max(prior_k.abs());
    let k = if stiffness_held { prior_k } else { k };
    Some((k, l, stiffness_held, damping_held, ek, el))
}

/// Fits one law to per-fold moments (contiguous folds, in time order): the parameters from all folds,
/// the fitness of each fold from a fit to the others.
pub fn fit_folds(
    kind: Kind,
    exponents: Exponents,
    folds: &[Moments],
    prior: Prior,
    cfg: &FitConfig,
) -> Result<Fit, ContactError> {
    let all = folds.iter().fold(Moments::default(), |acc, m| acc.plus(m));
    let (k, l, stiffness_held, damping_held, ek, el) =
        guarded_solve(&all, prior, cfg).ok_or(ContactError::NotEnoughData { kind: kind.id() })?;
    let overall_mean = if all.n > 0.0 { all.sf / all.n } else { 0.0 };
    let mut scores = Vec::with_capacity(folds.len());
    for (i, test) in folds.iter().enumerate() {
        let train =
            folds.iter().enumerate().filter(|(j, _)| *j != i).fold(Moments::default(), |acc, (_, m)| acc.plus(m));
        // Each training set is solved the way the full fit was: free, with λ held, or not at all.
        let params = match (stiffness_held, damping_held) {
            (false, false) => train.solve().or_else(|| train.solve_stiffness(l).map(|k| (k, l))),
            (false, true) => train.solve_stiffness(l).map(|k| (k, l)),
            (true, _) => Some((k, l)),
        };
        if let Some((kt, lt)) = params {
            let sst = if cfg.score_about_overall_mean { test.sst_about(overall_mean) } else { test.sst() };
            let score = fitness(test.sse(kt, lt), sst);
            if score.is_finite() {
                scores.push(score);
            }
        }
    }
    let n = scores.len() as f64;
    let mean = scores.iter().sum::<f64>() / n;
    let std = if n > 1.0 { (scores.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() } else { 0.0 };
    Ok(Fit {
        kind,
        exponents,
        stiffness: k,
        damping: l,
        stiffness_error: ek,
        damping_error: el,
        stiffness_held,
        damping_held,
        fitness_mean: if scores.is_empty() { f64::NAN } else { mean },
        fitness_std: std,
        fitness_all: fitness(all.sse(k, l), all.sst()),
        samples: all.n.round() as usize,
    })
}

/// The fold of sample i of n: contiguous blocks of (nearly) equal size, in time order.
#[inline]
pub fn fold_of(i: usize, n: usize, folds: usize) -> usize {
    i * folds / n
}

/// Per-fold moments of samples in time order.
pub fn fold_moments(samples: &[Sample], e: &Exponents, folds: usize) -> Vec<Moments> {
    let mut out = vec![Moments::default(); folds];
    for (i, s) in samples.iter().enumerate() {
        let (x1, x2) = regressors(e, s.z, s.zdot);
        out[fold_of(i, samples.len(), folds)].add(x1, x2, s.f, 1.0);
    }
    out
}

/// Cross-validated fit of one law with known exponents.
pub fn fit(
    kind: Kind,
    exponents: Exponents,
    samples: &[Sample],
    prior: Prior,
    cfg: &FitConfig,
) -> Result<Fit, ContactError> {
    if cfg.folds < 2 || samples.len() < 2 * cfg.folds {
        return Err(ContactError::NotEnoughData { kind: kind.id() });
    }
    fit_folds(kind, exponents, &fold_moments(samples, &exponents, cfg.folds), prior, cfg)
}

/// Weighted least squares of f ≈ k x₁ + λ x₂ by QR (faer), without forming normal equations: the
/// reference solver, and the inner solve of the robust fit.
pub fn least_squares_qr(
    samples: &[Sample],
    e: &Exponents,
    weights: Option<&[f64]>,
) -> Result<(f64, f64), ContactError> {
    let n = samples.len();
    let w = |i: usize| weights.map_or(1.0, |w| w[i].max(0.0).sqrt());
    let a = Mat::from_fn(n, 2, |i, j| {
        let (x1, x2) = regressors(e, samples[i].z, samples[i].zdot);
        w(i) * if j == 0 { x1 } else { x2 }
    });
    let b = Mat::from_fn(n, 1, |i, _| w(i) * samples[i].f);
    let x = a.qr().solve_lstsq(&b);
    let (k, l) = (x[(0, 0)], x[(1, 0)]);
    if k.is_finite() && l.is_finite() { Ok((k, l)) } else { Err(ContactError::NotEnoughData { kind: "least squares" }) }
}

/// Robust fit against outliers: iteratively reweighted least squares with Huber weights (threshold
/// 1.345 σ, σ from the median absolute residual), each step solved by QR.
pub fn robust_least_squares(samples: &[Sample], e: &Exponents, iterations: usize) -> Result<(f64, f64), ContactError> {
    let mut weights = vec![1.0; samples.len()];
    let mut params = least_squares_qr(samples, e, None)?;
    for _ in 0..iterations {
        let mut residuals: Vec<f64> = samples
            .iter()
            .map(|s| {
                let (x1, x2) = regressors(e, s.z, s.zdot);
                s.f - params.0 * x1 - params.1 * x2
            })
            .collect();
        let mut abs: Vec<f64> = residuals.iter().map(|r| r.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let sigma = (abs[abs.len() / 2] / 0.6745).max(1e-12);
        let threshold = 1.345 * sigma;
        for (w, r) in weights.iter_mut().zip(residuals.iter_mut()) {
            *w = if r.abs() <= threshold { 1.0 } else { threshold / r.abs() };
        }
        let next = least_squares_qr(samples, e, Some(&weights))?;
        let converged = (next.0 - params.0).abs() <= 1e-12 * next.0.abs()
            && (next.1 - params.1).abs() <= 1e-12 * next.1.abs().max(1.0);
        params = next;
        if converged {
            break;
        }
    }
    Ok(params)
}
