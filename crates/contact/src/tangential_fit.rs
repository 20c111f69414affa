//! Which tangential law a set of recorded paths shows, with its k_t and μ.
//!
//! Both laws of [`crate::tangential`] are fitted to the measured tangential force along every path —
//! Walton's T = k_t √δ_n δ_t (path-independent) and the incremental Mindlin–Deresiewicz law (path-
//! dependent) — and scored by K-fold cross-validation over whole paths: a path is never split between
//! fitting and scoring, since the incremental law's state runs along it. The path-independent law is
//! kept unless the incremental one predicts the held-out paths better by more than `MARGIN`: on straight
//! paths from the zero the two are the same law (the snake paper's linear paths cannot tell them apart), and only
//! paths that turn (the snake paper's two-segment paths) or slide can.
//!
//! Fitting, per law: for each μ of a grid (and no slip), k_t by least squares (exact for Walton without
//! its cap and for the incremental law without slip, where T is linear in k_t; a few rescaling steps
//! otherwise), the best (k_t, μ) kept. μ is *identified* only when the data slide: when friction as high
//! as `NO_SLIP` fits within 1 % of the best, the data put only a lower bound on μ, and it is reported as
//! such (`friction_at_least`).

use crate::model::finite;
use crate::{ContactError, MindlinDeresiewicz, Tangential, TangentialLaw};

/// One sample along a path: normal deformation z \[m\] (from the zero), tangential displacement δ_t \[m\]
/// (signed, from where contact began, along the path's tangential axis), the normal force P \[N\] the law
/// sees, and the measured tangential force T \[N\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathSample {
    pub normal_displacement: f64,
    pub tangential_displacement: f64,
    pub normal_force: f64,
    pub tangential_force: f64,
}

/// One law fitted: its parameters, the RMS of its residual on the data it was fitted to, and on held-out
/// paths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentialFit {
    pub law: Tangential,
    /// Whether the data slide enough to identify μ; if not, `law.friction` is `NO_SLIP` and
    /// `friction_at_least` the lowest μ that fits as well.
    pub friction_identified: bool,
    pub friction_at_least: f64,
    pub rms: f64,
    pub cv_rms: f64,
}

/// Both laws fitted and the one chosen.
#[derive(Debug, Clone, PartialEq)]
pub struct TangentialIdentification {
    pub walton: TangentialFit,
    pub mindlin_deresiewicz: TangentialFit,
    pub chosen: TangentialLaw,
    pub folds: usize,
    pub paths: usize,
    pub samples: usize,
}

impl TangentialIdentification {
    pub fn chosen_fit(&self) -> &TangentialFit {
        match self.chosen {
            TangentialLaw::Walton => &self.walton,
            TangentialLaw::MindlinDeresiewicz => &self.mindlin_deresiewicz,
        }
    }
}

/// μ standing for "no slip": far above any rubber's.
pub const NO_SLIP: f64 = 1e9;
/// The incremental law is chosen only if its cross-validated RMS is below Walton's by this fraction.
pub const MARGIN: f64 = 0.05;
/// The friction grid [μ], coarse, then refined about its best.
const FRICTION_GRID: [f64; 14] = [0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0, 1.3, 1.7, 2.2, 3.0];

/// The tangential force `law` predicts at each sample of `path`.
pub fn predict(law: &Tangential, path: &[PathSample]) -> Result<Vec<f64>, ContactError> {
    let mut out = Vec::with_capacity(path.len());
    let mut md = MindlinDeresiewicz::default();
    for s in path {
        let (z, p) = (s.normal_displacement, s.normal_force);
        out.push(match law.law {
            TangentialLaw::Walton => {
                let (z, d, p) = (finite("z", z)?, finite("δ_t", s.tangential_displacement)?, finite("P", p)?);
                if z > 0.0 && p > 0.0 {
                    let cap = law.friction * p;
                    (law.stiffness * z.sqrt() * d).clamp(-cap, cap)
                } else {
                    0.0
                }
            }
            TangentialLaw::MindlinDeresiewicz => md.step(law, z, s.tangential_displacement, p)?.0,
        });
    }
    Ok(out)
}

/// `paths` as the tangential law sees them: each δ_n deepened by the found zero's depth below the surface
/// and the normal force Hertz's, k_n z^{3/2} (a measured force's noise would make the incremental law's
/// slip test flicker).
pub fn with_hertz(paths: &[Vec<PathSample>], k_n: f64, zero_depth: f64) -> Vec<Vec<PathSample>> {
    let sample = |s: &PathSample| {
        let z = s.normal_displacement + zero_depth;
        PathSample { normal_displacement: z, normal_force: k_n * z.max(0.0).powf(1.5), ..*s }
    };
    paths.iter().map(|p| p.iter().map(sample).collect()).collect()
}

/// The samples of `path` at least `spacing` \[m\] apart in the (δ_n, δ_t) plane, and its last: the laws
/// are exact on straight steps, so a dense recording fits the same with a fraction of its samples.
pub fn thinned(path: &[PathSample], spacing: f64) -> Vec<PathSample> {
    let mut out: Vec<PathSample> = Vec::new();
    for s in path {
        let far = out.last().is_none_or(|l| {
            (s.normal_displacement - l.normal_displacement).hypot(s.tangential_displacement - l.tangential_displacement)
                >= spacing
        });
        if far {
            out.push(*s);
        }
    }
    if let (Some(last), Some(kept)) = (path.last(), out.last())
        && last != kept
    {
        out.push(*last);
    }
    out
}

/// Sum of squared residuals of `law` over `paths`, and the sums Σ T·T̂ and Σ T̂² that rescale k_t.
fn residuals(law: &Tangential, paths: &[&[PathSample]]) -> Result<(f64, f64, f64), ContactError> {
    let (mut sse, mut tp, mut pp) = (0.0, 0.0, 0.0);
    for path in paths {
        for (s, t) in path.iter().zip(predict(law, path)?) {
            let r = s.tangential_force - t;
            (sse, tp, pp) = (sse + r * r, tp + s.tangential_force * t, pp + t * t);
        }
    }
    Ok((sse, tp, pp))
}

/// k_t of `law` (kind and μ given) by least squares; its sum of squared residuals.
fn fit_stiffness(kind: TangentialLaw, friction: f64, paths: &[&[PathSample]]) -> Result<(f64, f64), ContactError> {
    // Start from Walton's least squares without a cap: exact where nothing slides.
    let (mut xy, mut xx) = (0.0, 0.0);
    for s in paths.iter().flat_map(|p| p.iter()).filter(|s| s.normal_displacement > 0.0) {
        let x = s.normal_displacement.sqrt() * s.tangential_displacement;
        (xy, xx) = (xy + x * finite("T", s.tangential_force)?, xx + x * x);
    }
    if xx.is_nan() || xx <= 0.0 {
        return Err(ContactError::NotEnoughData { kind: "tangential law (no tangential motion in contact)" });
    }
    let mut law = Tangential { stiffness: (xy / xx).max(0.0), friction, law: kind };
    // T is linear in k_t except where the contact slips: rescale until the least-squares factor is 1.
    let mut sse = f64::INFINITY;
    for _ in 0..8 {
        let (e, tp, pp) = residuals(&law, paths)?;
        sse = e;
        if pp.is_nan() || pp <= 0.0 {
            break;
        }
        let scale = tp / pp;
        if (scale - 1.0).abs() < 1e-7 || scale.is_nan() || scale <= 0.0 {
            break;
        }
        law.stiffness *= scale;
    }
    Ok((law.stiffness, sse))
}

/// One law fitted to `paths`: the best (k_t, μ) over the friction grid and no slip, the grid refined
/// by golden section about its best; whether μ is identified.
fn fit_law(kind: TangentialLaw, paths: &[&[PathSample]]) -> Result<(Tangential, f64, bool, f64), ContactError> {
    let (k_free, sse_free) = fit_stiffness(kind, NO_SLIP, paths)?;
    let mut trials = Vec::with_capacity(FRICTION_GRID.len());
    for &mu in &FRICTION_GRID {
        trials.push((mu, fit_stiffness(kind, mu, paths)?));
    }
    let (i, &(mut mu, (mut k, mut sse))) =
        trials.iter().enumerate().min_by(|a, b| a.1.1.1.total_cmp(&b.1.1.1)).expect("a non-empty grid");
    // Refine between the grid's neighbours (golden section on μ, k_t refitted at each).
    if sse < 0.99 * sse_free && i + 1 < trials.len() {
        let (mut lo, mut hi) = (trials[i.saturating_sub(1)].0, trials[i + 1].0);
        for _ in 0..12 {
            let (a, b) = (hi - 0.618 * (hi - lo), lo + 0.618 * (hi - lo));
            let (fa, fb) = (fit_stiffness(kind, a, paths)?, fit_stiffness(kind, b, paths)?);
            if fa.1 < fb.1 {
                hi = b
            } else {
                lo = a
            }
            for (m, f) in [(a, fa), (b, fb)] {
                if f.1 < sse {
                    (mu, k, sse) = (m, f.0, f.1);
                }
            }
        }
    }
    // Friction is identified when no slip fits clearly worse than the best; otherwise report the lowest
    // μ of the grid that fits as well as no slip.
    if sse < 0.99 * sse_free {
        Ok((Tangential { stiffness: k, friction: mu, law: kind }, sse, true, mu))
    } else {
        let at_least = trials.iter().find(|(_, (_, e))| *e <= 1.01 * sse_free).map_or(NO_SLIP, |t| t.0);
        Ok((Tangential { stiffness: k_free, friction: NO_SLIP, law: kind }, sse_free, false, at_least))
    }
}

/// Both laws fitted to `paths` (each a sequence of samples from the start of contact) and scored by
/// `folds`-fold cross-validation over whole paths (path i held out in fold i mod folds); the incremental
/// law chosen only where it predicts held-out paths better by more than `MARGIN`.
pub fn identify_tangential(paths: &[Vec<PathSample>], folds: usize) -> Result<TangentialIdentification, ContactError> {
    let paths: Vec<&[PathSample]> = paths.iter().map(Vec::as_slice).filter(|p| !p.is_empty()).collect();
    let folds = folds.clamp(2, 10).min(paths.len());
    if folds < 2 {
        return Err(ContactError::NotEnoughData { kind: "tangential law (at least two paths)" });
    }
    let samples: usize = paths.iter().map(|p| p.len()).sum();
    let fit = |kind| -> Result<TangentialFit, ContactError> {
        let (law, sse, friction_identified, friction_at_least) = fit_law(kind, &paths)?;
        let mut held_out = 0.0;
        for f in 0..folds {
            let train: Vec<&[PathSample]> =
                paths.iter().enumerate().filter(|(i, _)| i % folds != f).map(|p| *p.1).collect();
            let test: Vec<&[PathSample]> =
                paths.iter().enumerate().filter(|(i, _)| i % folds == f).map(|p| *p.1).collect();
            let (fold_law, ..) = fit_law(kind, &train)?;
            held_out += residuals(&fold_law, &test)?.0;
        }
        let n = samples as f64;
        Ok(TangentialFit {
            law,
            friction_identified,
            friction_at_least,
            rms: (sse / n).sqrt(),
            cv_rms: (held_out / n).sqrt(),
        })
    };
    let walton = fit(TangentialLaw::Walton)?;
    let mindlin_deresiewicz = fit(TangentialLaw::MindlinDeresiewicz)?;
    let chosen = if mindlin_deresiewicz.cv_rms < (1.0 - MARGIN) * walton.cv_rms {
        TangentialLaw::MindlinDeresiewicz
    } else {
        TangentialLaw::Walton
    };
    Ok(TangentialIdentification { walton, mindlin_deresiewicz, chosen, folds, paths: paths.len(), samples })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ContactModel, Kind, N_PER_MM_1_5, seed_000_experiments};

    /// Samples every `step` along `path` of the (δ_n, δ_t) plane, with P = k_n z^{3/2} and T from
    /// `truth` (Walton: its closed form written here; the incremental law: stepped along the path), plus
    /// an offset-free noise of `noise` N (a fixed pseudo-random sequence).
    fn sampled(path: &[[f64; 2]], truth: &Tangential, step: f64, noise: f64, seed: &mut u64) -> Vec<PathSample> {
        let k_n = 8.280 * N_PER_MM_1_5;
        let mut md = MindlinDeresiewicz::default();
        let mut out = Vec::new();
        let mut from = [0.0, 0.0];
        for w in path {
            let steps = (((w[0] - from[0]).hypot(w[1] - from[1]) / step).ceil() as usize).max(1);
            for k in 1..=steps {
                let u = k as f64 / steps as f64;
                let (z, d) = (from[0] + u * (w[0] - from[0]), from[1] + u * (w[1] - from[1]));
                let p = k_n * z.max(0.0).powf(1.5);
                let t = match truth.law {
                    TangentialLaw::Walton => {
                        (truth.stiffness * z.sqrt() * d).clamp(-truth.friction * p, truth.friction * p)
                    }
                    TangentialLaw::MindlinDeresiewicz => md.step(truth, z, d, p).unwrap().0,
                };
                *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let r = ((*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0 * 3f64.sqrt();
                out.push(PathSample {
                    normal_displacement: z,
                    tangential_displacement: d,
                    normal_force: p,
                    tangential_force: t + noise * r,
                });
            }
            from = *w;
        }
        out
    }

    fn seed_000_paths(linear_only: bool) -> Vec<Vec<[f64; 2]>> {
        let m = ContactModel::new(Kind::HertzWalton, 8.280 * N_PER_MM_1_5, 0.0).unwrap();
        let all = seed_000_experiments(&m, 2e-3).unwrap();
        let keep = |f: crate::Family| if linear_only { f == crate::Family::Linear } else { f != crate::Family::Normal };
        all.into_iter().filter(|p| keep(p.family)).map(|p| p.waypoints).collect()
    }

    fn data(truth: Tangential, linear_only: bool) -> Vec<Vec<PathSample>> {
        let mut seed = 7;
        seed_000_paths(linear_only).iter().map(|p| sampled(p, &truth, 40e-6, 0.02, &mut seed)).collect()
    }

    const K_T: f64 = 3.7482 * N_PER_MM_1_5;

    #[test]
    fn the_incremental_law_is_named_on_paths_that_turn_and_its_k_t_recovered() {
        let id = identify_tangential(&data(Tangential::mindlin_deresiewicz(K_T, 0.9), false), 5).unwrap();
        eprintln!("{id:?}");
        assert_eq!(id.chosen, TangentialLaw::MindlinDeresiewicz);
        let md = id.mindlin_deresiewicz;
        assert!((md.law.stiffness / K_T - 1.0).abs() < 0.01, "k_t {}", md.law.stiffness / N_PER_MM_1_5);
        // The held-out error of the right law is the noise's (0.02 N); Walton's carries the path dependence.
        assert!(md.cv_rms < 0.03 && id.walton.cv_rms > 3.0 * md.cv_rms, "{id:?}");
    }

    #[test]
    fn walton_data_keep_walton_and_straight_paths_cannot_tell_the_laws_apart() {
        let id = identify_tangential(&data(Tangential::walton(K_T, 0.9), false), 5).unwrap();
        assert_eq!(id.chosen, TangentialLaw::Walton, "{id:?}");
        assert!((id.walton.law.stiffness / K_T - 1.0).abs() < 0.01);
        // The snake paper's linear paths only: the incremental truth, yet the laws agree on every straight path.
        let id = identify_tangential(&data(Tangential::mindlin_deresiewicz(K_T, 0.9), true), 5).unwrap();
        assert_eq!(id.chosen, TangentialLaw::Walton, "{id:?}");
        assert!((id.walton.cv_rms / id.mindlin_deresiewicz.cv_rms - 1.0).abs() < 0.01, "{id:?}");
        assert!((id.walton.law.stiffness / K_T - 1.0).abs() < 0.01);
    }

    #[test]
    fn friction_is_identified_where_the_contact_slides_and_bounded_where_it_does_not() {
        // Pressed 1 mm, then dragged 1.5 mm sideways at constant depth (Cattaneo–Mindlin, then sliding),
        // and back: μ = 0.6 shows.
        let truth = Tangential::mindlin_deresiewicz(K_T, 0.6);
        let mut seed = 3;
        let paths: Vec<Vec<PathSample>> = (0..6)
            .map(|i| {
                let depth = 0.6e-3 + 0.2e-3 * i as f64;
                sampled(&[[depth, 0.0], [depth, 1.5e-3], [depth, 0.0]], &truth, 10e-6, 0.02, &mut seed)
            })
            .collect();
        let id = identify_tangential(&paths, 3).unwrap();
        let md = id.mindlin_deresiewicz;
        assert_eq!(id.chosen, TangentialLaw::MindlinDeresiewicz, "{id:?}");
        assert!(md.friction_identified && (md.law.friction / 0.6 - 1.0).abs() < 0.03, "{md:?}");
        assert!((md.law.stiffness / K_T - 1.0).abs() < 0.03, "{md:?}");
        // The linear paths never slide (dT/dP ≤ 0.385 < μ): only a lower bound.
        let id = identify_tangential(&data(Tangential::mindlin_deresiewicz(K_T, 0.9), true), 5).unwrap();
        assert!(!id.walton.friction_identified && id.walton.friction_at_least <= 0.5, "{id:?}");
    }

    #[test]
    fn bad_data_is_refused() {
        assert!(identify_tangential(&[], 5).is_err());
        let s = PathSample {
            normal_displacement: 1e-3,
            tangential_displacement: 0.0,
            normal_force: 5.0,
            tangential_force: 0.0,
        };
        // No tangential motion.
        assert!(identify_tangential(&[vec![s; 10], vec![s; 10]], 5).is_err());
        let mut bad = data(Tangential::walton(K_T, 0.9), true);
        bad[3][5].tangential_force = f64::NAN;
        assert!(identify_tangential(&bad, 5).is_err());
        bad[3][5].tangential_force = 0.0;
        bad[1][2].normal_displacement = f64::INFINITY;
        assert!(identify_tangential(&bad, 5).is_err());
    }
}
