//! The snake paper's loading-path experiments ("Frictional Compliance Model Development and
//! Experiments for Snake Robot Climbing", section IV): paths in the (δ_n, δ_t) plane along which a plate is pushed onto a compliant
//! half-ball, and what a contact model predicts at their ends.
//!
//! - 10 normal loadings, (0, 0) → (δ_max, 0);
//! - 45 linear paths, 2° … 30° by 2°, three repeats each, to the same normal depth δ_max;
//! - 150 two-segment paths in three sets converging on 5 points equally spaced along the 20° ray (up to
//!   δ_n = `last_point`): approach angles 10–30° by 5°, 16–24° by 2° and 18–22° by 1°, each path twice.
//!   The snake paper does not define its two segments; these are "corner" paths: from the origin along the
//!   approach angle α until the path meets the axis-parallel line through the convergence point, then
//!   along that line to it — for α < 20° the last segment is purely tangential, for α > 20° purely normal
//!   (α = 20° is the straight ray).
//!
//! δ_max is where the normal law reaches 25 N ([`ContactModel::deformation_for_force`]). A model whose
//! tangential force depends on the present displacement only (Walton's) predicts one force per
//! convergence point; the incremental Mindlin–Deresiewicz law predicts a spread
//! ([`predicted_dispersion`]), the spread the snake paper measured (its Table III) and could not model.

use crate::{ContactError, ContactModel, Dispersion, MindlinDeresiewicz, TangentialLaw, dispersion};

/// The snake paper gives its stiffnesses in N/mm^{3/2}; the models take N/m^{3/2}: multiply by this (1000^{3/2}).
pub const N_PER_MM_1_5: f64 = 31_622.776_601_683_792;

/// Which of the snake paper's experiment families a path belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Family {
    Normal,
    Linear,
    /// Two-segment paths, set 1, 2 or 3.
    TwoSegment(u8),
}

/// One experiment: straight segments through `waypoints` from (0, 0), in the (δ_n, δ_t) plane \[m\].
#[derive(Debug, Clone, PartialEq)]
pub struct LoadingPath {
    pub family: Family,
    /// The approach angle [°] from the δ_n axis: 0 for normal loading.
    pub angle: f64,
    /// Which convergence point (0–4) a two-segment path ends on.
    pub point: Option<usize>,
    pub repeat: usize,
    pub waypoints: Vec<[f64; 2]>,
}

impl LoadingPath {
    pub fn end(&self) -> [f64; 2] {
        *self.waypoints.last().expect("a path has at least one waypoint")
    }

    /// The path's length in the (δ_n, δ_t) plane \[m\].
    pub fn length(&self) -> f64 {
        let mut from = [0.0, 0.0];
        let mut length = 0.0;
        for w in &self.waypoints {
            length += (w[0] - from[0]).hypot(w[1] - from[1]);
            from = *w;
        }
        length
    }
}

/// The approach angles [°] of the three two-segment sets.
pub const SET_ANGLES: [&[f64]; 3] =
    [&[10.0, 15.0, 20.0, 25.0, 30.0], &[16.0, 18.0, 20.0, 22.0, 24.0], &[18.0, 19.0, 20.0, 21.0, 22.0]];
/// The ray the convergence points lie on [°].
pub const CONVERGENCE_ANGLE: f64 = 20.0;
/// Every experiment runs to this normal force \[N\] (normal and linear paths).
pub const FINAL_NORMAL_FORCE: f64 = 25.0;

/// The convergence points: 5 equally spaced along the 20° ray, the last `last_point` deep \[m\].
pub fn convergence_points(last_point: f64) -> [[f64; 2]; 5] {
    let slope = CONVERGENCE_ANGLE.to_radians().tan();
    std::array::from_fn(|j| {
        let dn = last_point * (j + 1) as f64 / 5.0;
        [dn, dn * slope]
    })
}

/// The corner path at approach angle `angle` [°] to `point` on the 20° ray (see the module docs).
pub fn corner_path(angle: f64, point: [f64; 2]) -> Vec<[f64; 2]> {
    let (ta, tb) = (angle.to_radians().tan(), CONVERGENCE_ANGLE.to_radians().tan());
    let [dn, dt] = point;
    if (ta - tb).abs() <= 1e-12 {
        vec![point]
    } else if ta < tb {
        vec![[dn, dn * ta], point]
    } else {
        vec![[dt / ta, dt], point]
    }
}

/// The snake paper's 205 experiments for a specimen whose normal law is `model`'s, with the convergence points
/// up to `last_point` deep \[m\].
pub fn seed_000_experiments(model: &ContactModel, last_point: f64) -> Result<Vec<LoadingPath>, ContactError> {
    let depth = model.deformation_for_force(FINAL_NORMAL_FORCE)?;
    if !(last_point > 0.0 && last_point.is_finite()) {
        return Err(ContactError::InvalidConfig(format!("the last convergence point must be > 0 deep ({last_point})")));
    }
    let mut paths = Vec::with_capacity(205);
    for repeat in 0..10 {
        paths.push(LoadingPath {
            family: Family::Normal,
            angle: 0.0,
            point: None,
            repeat,
            waypoints: vec![[depth, 0.0]],
        });
    }
    for step in 1..=15 {
        let angle = 2.0 * step as f64;
        for repeat in 0..3 {
            let waypoints = vec![[depth, depth * angle.to_radians().tan()]];
            paths.push(LoadingPath { family: Family::Linear, angle, point: None, repeat, waypoints });
        }
    }
    for (set, angles) in SET_ANGLES.iter().enumerate() {
        for (point, target) in convergence_points(last_point).into_iter().enumerate() {
            for &angle in angles.iter() {
                for repeat in 0..2 {
                    paths.push(LoadingPath {
                        family: Family::TwoSegment(set as u8 + 1),
                        angle,
                        point: Some(point),
                        repeat,
                        waypoints: corner_path(angle, target),
                    });
                }
            }
        }
    }
    Ok(paths)
}

/// The forces (f_n, f_t) \[N\] the model predicts at the end of `path`, walked quasi-statically in `steps`
/// steps a segment: the normal law at rest and the model's tangential law — Walton's from the end point
/// alone, Mindlin–Deresiewicz's integrated along the path.
pub fn forces_at_end(model: &ContactModel, path: &LoadingPath, steps: usize) -> Result<(f64, f64), ContactError> {
    let Some(law) = model.tangential else {
        return Err(ContactError::InvalidModel("predicting tangential forces needs a tangential law".into()));
    };
    let [dn, dt] = path.end();
    let normal = model.force(dn, 0.0)?;
    match law.law {
        TangentialLaw::Walton => Ok((normal, model.tangential_force(dn, dt, normal)?.map_or(0.0, |(t, _)| t))),
        TangentialLaw::MindlinDeresiewicz => {
            let mut md = MindlinDeresiewicz::default();
            let (mut from, mut t) = ([0.0, 0.0], 0.0);
            for w in &path.waypoints {
                for k in 1..=steps.max(1) {
                    let u = k as f64 / steps.max(1) as f64;
                    let (z, d) = (from[0] + u * (w[0] - from[0]), from[1] + u * (w[1] - from[1]));
                    t = md.step(&law, z, d, model.force(z, 0.0)?)?.0;
                }
                from = *w;
            }
            Ok((normal, t))
        }
    }
}

/// The snake paper's Table III statistics as `model` predicts them for two-segment set `set` (1–3): the forces
/// at the end of every path of the set, grouped by convergence point. Zero for Walton's law.
pub fn predicted_dispersion(
    model: &ContactModel,
    paths: &[LoadingPath],
    set: u8,
    steps: usize,
) -> Result<Dispersion, ContactError> {
    let mut groups: Vec<Vec<(f64, f64)>> = vec![Vec::new(); 5];
    for path in paths.iter().filter(|p| p.family == Family::TwoSegment(set)) {
        let point = path.point.expect("two-segment paths end on a convergence point");
        groups[point].push(forces_at_end(model, path, steps)?);
    }
    dispersion(&groups)
}

/// The snake paper's eq. 4 normal part fitted by least squares: k_n of f_n = k_n δ_n^{3/2}, from (δ_n, f_n)
/// samples (those with δ_n > 0). A model linear in its one parameter: k = Σ f x / Σ x², x = δ_n^{3/2}.
pub fn fit_normal_stiffness(samples: &[(f64, f64)]) -> Result<f64, ContactError> {
    fit_through_origin(samples.iter().filter(|s| s.0 > 0.0).map(|&(dn, f)| (dn.powf(1.5), f)), "k_n")
}

/// The snake paper's zero (the third reading above a threshold) lies below the true surface: Hertz's law
/// fitted with the depth of the zero as a second parameter, f_n = k_n (δ_n + z_0)^{3/2} over z_0 in
/// [0, `max_zero`] (k_n by least squares at each); (k_n, z_0). Without z_0 a fitted k_t absorbs the
/// missing √z_0 and a fitted μ the curvature it leaves.
pub fn fit_normal_stiffness_and_zero(samples: &[(f64, f64)], max_zero: f64) -> Result<(f64, f64), ContactError> {
    let shifted = |z0: f64| samples.iter().map(move |&(dn, f)| (dn + z0, f)).filter(|s| s.0 > 0.0);
    let rss = |z0: f64| {
        let k = fit_through_origin(shifted(z0).map(|(z, f)| (z.powf(1.5), f)), "k_n").unwrap_or(f64::NAN);
        shifted(z0).map(|(z, f)| (f - k * z.powf(1.5)).powi(2)).sum::<f64>()
    };
    let (z0, _, _) = crate::minimize_scalar(rss, 0.0, max_zero.max(0.0), 20, 1e-9);
    Ok((fit_through_origin(shifted(z0).map(|(z, f)| (z.powf(1.5), f)), "k_n")?, z0))
}

/// The snake paper's eq. 4 tangential part fitted by least squares: k_t of f_t = k_t √δ_n δ_t, from
/// (δ_n, δ_t, f_t) samples (those with δ_n > 0).
pub fn fit_tangential_stiffness(samples: &[(f64, f64, f64)]) -> Result<f64, ContactError> {
    fit_through_origin(samples.iter().filter(|s| s.0 > 0.0).map(|&(dn, dt, f)| (dn.sqrt() * dt, f)), "k_t")
}

fn fit_through_origin(points: impl Iterator<Item = (f64, f64)>, name: &'static str) -> Result<f64, ContactError> {
    let (mut xy, mut xx) = (0.0, 0.0);
    for (x, y) in points {
        if !(x.is_finite() && y.is_finite()) {
            return Err(ContactError::NonFinite { name, value: if x.is_finite() { y } else { x } });
        }
        (xy, xx) = (xy + x * y, xx + x * x);
    }
    if xx <= 0.0 {
        return Err(ContactError::NotEnoughData { kind: name });
    }
    Ok(xy / xx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_unit_factor_is_1000_to_the_three_halves() {
        assert!((N_PER_MM_1_5 / 1000f64.powf(1.5) - 1.0).abs() < 1e-15);
    }
    use crate::{Kind, Tangential};

    /// The snake paper's fitted linear-path constants in SI: k_n 8.280 N/mm^1.5, k_t 3.7482 N/mm^1.5.
    fn specimen(law: Tangential) -> ContactModel {
        let per_mm = N_PER_MM_1_5;
        let mut m = ContactModel::new(Kind::HertzWalton, 8.280 * per_mm, 0.0).unwrap();
        m.tangential = Some(Tangential { stiffness: 3.7482 * per_mm, ..law });
        m
    }

    #[test]
    fn eq_4_fits_recover_the_constants_and_refuse_what_they_cannot_use() {
        let normal: Vec<(f64, f64)> =
            (1..50).map(|k| (k as f64 * 1e-5, 8.28e5 * (k as f64 * 1e-5f64).powf(1.5))).collect();
        assert!((fit_normal_stiffness(&normal).unwrap() - 8.28e5).abs() < 1e-6);
        let tangential: Vec<(f64, f64, f64)> = (1..50)
            .map(|k| (k as f64 * 1e-5, k as f64 * 3e-6, 3.7e5 * (k as f64 * 1e-5f64).sqrt() * k as f64 * 3e-6))
            .collect();
        assert!((fit_tangential_stiffness(&tangential).unwrap() - 3.7e5).abs() < 1e-6);
        assert!(fit_normal_stiffness(&[(0.0, 1.0), (-1e-3, 2.0)]).is_err());
        assert!(fit_normal_stiffness(&[(1e-3, f64::NAN)]).is_err());
    }

    #[test]
    fn the_205_experiments_of_seed_000() {
        let model = specimen(Tangential::walton(0.0, 0.9));
        let paths = seed_000_experiments(&model, 2e-3).unwrap();
        let count = |f: Family| paths.iter().filter(|p| p.family == f).count();
        assert_eq!(paths.len(), 205);
        assert_eq!((count(Family::Normal), count(Family::Linear)), (10, 45));
        for set in 1..=3 {
            assert_eq!(count(Family::TwoSegment(set)), 50);
        }
        let depth = (25.0 / (8.280 * N_PER_MM_1_5)).powf(2.0 / 3.0);
        for p in paths.iter().filter(|p| matches!(p.family, Family::Normal | Family::Linear)) {
            let [dn, dt] = p.end();
            assert!((model.force(dn, 0.0).unwrap() - 25.0).abs() < 1e-9 && (dn - depth).abs() < 1e-15);
            assert!((dt.atan2(dn).to_degrees() - p.angle).abs() < 1e-9, "{p:?}");
        }
        // Two-segment paths: the first segment at the approach angle, the second parallel to an axis,
        // ending on a convergence point of the 20° ray; 5 approach angles per point, each twice.
        let points = convergence_points(2e-3);
        assert!((points[4][0] - 2e-3).abs() < 1e-18 && (points[0][0] - 0.4e-3).abs() < 1e-15);
        for p in paths.iter().filter(|p| matches!(p.family, Family::TwoSegment(_))) {
            let end = p.end();
            assert_eq!(end, points[p.point.unwrap()]);
            let first = p.waypoints[0];
            assert!((first[1].atan2(first[0]).to_degrees() - p.angle).abs() < 1e-9, "{p:?}");
            if p.angle == 20.0 {
                assert_eq!(p.waypoints.len(), 1);
            } else {
                assert_eq!(p.waypoints.len(), 2);
                assert!(first[0] == end[0] || first[1] == end[1], "axis-parallel second segment: {p:?}");
                assert!(first[0] <= end[0] && first[1] <= end[1], "both displacements grow: {p:?}");
            }
        }
    }

    #[test]
    fn walton_predicts_no_spread_and_mindlin_deresiewicz_a_spread_that_narrows_with_the_sets() {
        let walton = specimen(Tangential::walton(0.0, 0.9));
        let md = specimen(Tangential::mindlin_deresiewicz(0.0, 0.9));
        let paths = seed_000_experiments(&walton, 2e-3).unwrap();
        let mut previous = f64::INFINITY;
        for set in 1..=3 {
            let w = predicted_dispersion(&walton, &paths, set, 200).unwrap();
            assert!(w.total_error < 1e-12, "set {set}: Walton spreads {}", w.total_error);
            let m = predicted_dispersion(&md, &paths, set, 200).unwrap();
            eprintln!(
                "set {set}: MD total {:.3} N, mean normalized {:.2} %",
                m.total_error,
                100.0 * m.mean_normalized_error
            );
            assert!(m.mean_normalized_error > 0.0 && m.mean_normalized_error < previous, "set {set}: {m:?}");
            previous = m.mean_normalized_error;
        }
    }

    #[test]
    fn without_slip_the_spread_follows_from_the_corner_closed_forms() {
        // μ large: no microslip, so each path ends at T = T_W · r(α) with r from the closed forms
        // (1.5 − 0.5 tan α/tan 20° below 20°, √(tan 20°/tan α) above) and the normal force is Hertz's;
        // the dispersion computed from those closed forms must equal the law's.
        let md = specimen(Tangential::mindlin_deresiewicz(0.0, 1e9));
        let paths = seed_000_experiments(&md, 2e-3).unwrap();
        let tb = 20f64.to_radians().tan();
        let (kn, kt) = (8.280 * N_PER_MM_1_5, 3.7482 * N_PER_MM_1_5);
        for set in 1..=3u8 {
            let groups: Vec<Vec<(f64, f64)>> = convergence_points(2e-3)
                .iter()
                .map(|&[dn, dt]| {
                    SET_ANGLES[set as usize - 1]
                        .iter()
                        .flat_map(|&a| {
                            let ta = a.to_radians().tan();
                            let r = if ta <= tb { 1.5 - 0.5 * ta / tb } else { (tb / ta).sqrt() };
                            let f = (kn * dn.powf(1.5), r * kt * dn.sqrt() * dt);
                            [f, f]
                        })
                        .collect()
                })
                .collect();
            let expected = dispersion(&groups).unwrap();
            let predicted = predicted_dispersion(&md, &paths, set, 3).unwrap();
            assert!(
                (predicted.total_error - expected.total_error).abs() < 1e-9 * expected.total_error
                    && (predicted.mean_normalized_error - expected.mean_normalized_error).abs() < 1e-9,
                "set {set}: {predicted:?} vs {expected:?}"
            );
        }
    }
}
