//! A record's phases (free, approach, loading, holding, unloading) and its noise floor.

use super::*;

/// Phase of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// z ≤ 0 and not moving toward the surface.
    Free,
    /// z ≤ 0, moving toward the surface (ż > v_th).
    Approach,
    /// In contact, ż > v_th.
    Loading,
    /// In contact, |ż| ≤ v_th.
    Holding,
    /// In contact, ż < −v_th.
    Unloading,
}

impl Phase {
    pub fn in_contact(self) -> bool {
        matches!(self, Phase::Loading | Phase::Holding | Phase::Unloading)
    }

    pub const ALL: [Phase; 5] = [Phase::Free, Phase::Approach, Phase::Loading, Phase::Holding, Phase::Unloading];
}

/// The velocity threshold between moving and holding: 5 % of the 95th percentile of |ż|, and above the
/// jitter of ż (three times the robust σ of its sample-to-sample change). The percentile ignores the few
/// fastest samples (spikes of a differentiated position); 5 % of it is well below the speed of any
/// deliberate push, whatever the record's scale.
pub fn velocity_threshold(series: &Series) -> f64 {
    let mut d: Vec<f64> = series.zdot.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    d.sort_by(f64::total_cmp);
    let jitter = d.get(d.len() / 2).copied().unwrap_or(0.0) * 1.4826 / std::f64::consts::SQRT_2;
    (0.05 * p95_speed(series)).max(3.0 * jitter).max(f64::MIN_POSITIVE)
}

/// The speed that a quarter of the moving in-contact samples exceed [m/s]
/// ([`HYSTERESIS_SATURATION_PERCENTILE`]).
pub(crate) fn saturating_speed(series: &Series, v_th: f64) -> f64 {
    let mut v: Vec<f64> = series
        .zdot
        .iter()
        .zip(&series.z)
        .filter(|(zd, z)| **z > 0.0 && zd.abs() > v_th)
        .map(|(zd, _)| zd.abs())
        .collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * HYSTERESIS_SATURATION_PERCENTILE).round() as usize]
}

/// The 95th percentile of |ż| [m/s].
pub(crate) fn p95_speed(series: &Series) -> f64 {
    let mut v: Vec<f64> = series.zdot.iter().map(|x| x.abs()).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * 0.95).round() as usize]
}

/// The phase of every sample for the velocity threshold `v_th`.
pub fn phases(series: &Series, v_th: f64) -> Vec<Phase> {
    series
        .z
        .iter()
        .zip(&series.zdot)
        .map(|(&z, &zd)| {
            if z <= 0.0 {
                if zd > v_th { Phase::Approach } else { Phase::Free }
            } else if zd > v_th {
                Phase::Loading
            } else if zd < -v_th {
                Phase::Unloading
            } else {
                Phase::Holding
            }
        })
        .collect()
}

/// Where the noise floor came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseSource {
    /// Out-of-contact samples, after removing their mean and linear trend.
    FreeSpace,
    /// Out-of-contact samples with structure of their own (more than [`STRUCTURED_FREE_SPACE`] times the
    /// robust σ of their differences): that robust σ, 1.4826 · MAD(Δf) / √2.
    FreeSpaceDifferences,
    /// First differences of the force in holds: σ ≈ std(Δf)/√2.
    HoldingDifferences,
    /// First differences of all samples (an upper bound when nothing else is available).
    AllDifferences,
}

/// The force noise σ \[N\] and how it was measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NoiseFloor {
    pub sigma: f64,
    pub source: NoiseSource,
    pub samples: usize,
    /// σ of the noise averaged over [`Options::tare_window`] \[N\]: the error a tare's own reading leaves
    /// as an offset, and the level a slow noise (a low-passed sensor, a wandering offset) moves the force
    /// by. From the free samples' autocovariance up to that window; σ itself where free space has
    /// structure of its own or there is none.
    pub level_sigma: f64,
}

/// The fewest samples a noise estimate uses.
pub const MIN_NOISE_SAMPLES: usize = 20;

/// Free space whose σ about its trend exceeds this many times the robust σ of its differences carries
/// structure, not noise (see [`NoiseSource::FreeSpaceDifferences`]).
pub const STRUCTURED_FREE_SPACE: f64 = 3.0;

/// σ of the force noise: from the farther half of the out-of-contact samples (mean, linear trend in the
/// time since the last tare and, when the hand tilts, the gravity change removed) when there are at least [`MIN_NOISE_SAMPLES`], else from first differences in holds, else
/// from all first differences.
pub fn noise_floor(series: &Series, phases: &[Phase], tare_window: f64) -> NoiseFloor {
    // The trend is in the time since the last tare: a drifting sensor's offset restarts at each tare.
    let mut since = 0.0;
    let tared = series.tared_before();
    let clock: Vec<f64> = (0..series.len())
        .map(|i| {
            since = if i == 0 || tared[i] { 0.0 } else { since + series.t[i] - series.t[i - 1] };
            since
        })
        .collect();
    // The half of free space farther from the surface: samples just above a surface placed too deep may
    // still touch.
    let mut free: Vec<usize> = (0..series.len()).filter(|&i| series.z[i] <= 0.0).collect();
    if free.len() >= 2 * MIN_NOISE_SAMPLES {
        let mut depth: Vec<f64> = free.iter().map(|&i| series.z[i]).collect();
        depth.sort_by(f64::total_cmp);
        let median = depth[depth.len() / 2];
        free.retain(|&i| series.z[i] <= median);
    }
    if free.len() >= MIN_NOISE_SAMPLES {
        // Least squares on [1, time since tare, gravity change since tare]: what a tilting hand of unknown
        // weight adds in free space is structure, not noise.
        let tilts = series.gravity_change.len() == series.len()
            && free.iter().any(|&i| series.gravity_change[i] != series.gravity_change[free[0]]);
        let p = if tilts { 3 } else { 2 };
        let row = |i: usize| [1.0, clock[i], if tilts { series.gravity_change[i] } else { 0.0 }];
        let mut g = nalgebra::DMatrix::<f64>::zeros(p, p);
        let mut h = nalgebra::DVector::<f64>::zeros(p);
        for &i in &free {
            let r = row(i);
            for j in 0..p {
                h[j] += r[j] * series.f[i];
                for k in 0..p {
                    g[(j, k)] += r[j] * r[k];
                }
            }
        }
        let beta = g.clone().pseudo_inverse(1e-12).map(|inv| inv * h).unwrap_or_else(|_| nalgebra::DVector::zeros(p));
        let residual: Vec<f64> = free
            .iter()
            .map(|&i| {
                let r = row(i);
                series.f[i] - (0..p).map(|j| beta[j] * r[j]).sum::<f64>()
            })
            .collect();
        let sse: f64 = residual.iter().map(|r| r * r).sum();
        let n = free.len() as f64;
        let sigma = (sse / (n - p as f64)).sqrt();
        // Free space with structure of its own (an adhesion or a tether pulling after lift-off, a
        // long-range force before contact) is not noise: then the robust σ of consecutive free samples'
        // differences, which steps and slow pulls barely move.
        let mut steps: Vec<f64> =
            free.windows(2).filter(|w| w[1] == w[0] + 1).map(|w| series.f[w[1]] - series.f[w[0]]).collect();
        if steps.len() >= MIN_NOISE_SAMPLES {
            let robust = robust_noise_of_differences(&mut steps);
            if sigma > STRUCTURED_FREE_SPACE * robust {
                return NoiseFloor {
                    sigma: robust,
                    source: NoiseSource::FreeSpaceDifferences,
                    samples: steps.len(),
                    level_sigma: robust,
                };
            }
        }
        let level_sigma = level_sigma(series, &free, &residual, tare_window).min(sigma);
        return NoiseFloor { sigma, source: NoiseSource::FreeSpace, samples: free.len(), level_sigma };
    }
    let diffs = |keep: &dyn Fn(usize) -> bool| -> Vec<f64> {
        (1..series.len()).filter(|&i| keep(i)).map(|i| series.f[i] - series.f[i - 1]).collect()
    };
    let std = |d: &[f64]| {
        let m = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (d.len() as f64 - 1.0)).sqrt()
    };
    let hold = diffs(&|i| phases[i] == Phase::Holding && phases[i - 1] == Phase::Holding);
    if hold.len() >= MIN_NOISE_SAMPLES {
        let sigma = std(&hold) / 2f64.sqrt();
        return NoiseFloor { sigma, source: NoiseSource::HoldingDifferences, samples: hold.len(), level_sigma: sigma };
    }
    let all = diffs(&|_| true);
    let sigma = std(&all) / 2f64.sqrt();
    NoiseFloor { sigma, source: NoiseSource::AllDifferences, samples: all.len(), level_sigma: sigma }
}

/// The noise σ of a signal from its consecutive differences `d` (reordered): the median absolute
/// deviation, which steps and slow structure barely move, over √2. A quantised signal whose differences
/// are mostly zero has a deviation of zero, yet its reading is rounded to a step q: its σ is then at
/// least the rounding's, q/√12, q the least non-zero difference.
pub fn robust_noise_of_differences(d: &mut [f64]) -> f64 {
    if d.is_empty() {
        return 0.0;
    }
    d.sort_by(f64::total_cmp);
    let mid = d[d.len() / 2];
    let quantum = d.iter().map(|x| x.abs()).filter(|&x| x > 0.0).fold(f64::INFINITY, f64::min);
    let mut dev: Vec<f64> = d.iter().map(|x| (x - mid).abs()).collect();
    dev.sort_by(f64::total_cmp);
    let mad = 1.4826 * dev[dev.len() / 2] / 2f64.sqrt();
    if mad > 0.0 || !quantum.is_finite() { mad } else { quantum / 12f64.sqrt() }
}

/// σ of the mean of `window` seconds of noise, from the autocovariance γ(k) of the free samples' residual
/// (pairs of consecutive free samples only) over the m lags the window spans:
/// var = (γ(0) + 2 Σₖ₌₁^{m−1} (1 − k/m) γ(k)) / m.
pub(crate) fn level_sigma(series: &Series, free: &[usize], residual: &[f64], window: f64) -> f64 {
    let mut spacing: Vec<f64> =
        free.windows(2).filter(|w| w[1] == w[0] + 1).map(|w| series.t[w[1]] - series.t[w[0]]).collect();
    if spacing.is_empty() {
        return f64::INFINITY;
    }
    spacing.sort_by(f64::total_cmp);
    let dt = spacing[spacing.len() / 2].max(1e-300);
    let m = ((window / dt).round() as usize).clamp(1, free.len() / 4 + 1);
    let gamma = |k: usize| {
        let (mut sum, mut count) = (0.0, 0usize);
        for a in 0..free.len().saturating_sub(k) {
            if free[a + k] == free[a] + k {
                sum += residual[a] * residual[a + k];
                count += 1;
            }
        }
        if count == 0 { 0.0 } else { sum / count as f64 }
    };
    let mf = m as f64;
    let var = (gamma(0) + 2.0 * (1..m).map(|k| (1.0 - k as f64 / mf) * gamma(k)).sum::<f64>()) / mf;
    var.max(gamma(0) / mf).sqrt()
}

/// The dt handed to [`ContactModel::step`] at each sample: the spacing of the time stamps (the first
/// sample gets the second's spacing).
pub fn step_sizes(series: &Series) -> Vec<f64> {
    let n = series.len();
    (0..n)
        .map(|i| {
            if i > 0 {
                series.t[i] - series.t[i - 1]
            } else if n > 1 {
                series.t[1] - series.t[0]
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::robust_noise_of_differences;

    #[test]
    fn a_quantised_signal_has_at_least_its_roundings_noise_and_a_gaussian_its_own() {
        // A slow sine of amplitude 0.3 steps read through a converter of step 0.02: most consecutive
        // readings are equal, so the median absolute deviation is zero; the rounding's σ is 0.02/√12.
        let q = 0.02;
        let read: Vec<f64> = (0..2000).map(|i| ((0.3 * (i as f64 / 400.0).sin()) / q).round() * q).collect();
        let mut d: Vec<f64> = read.windows(2).map(|w| w[1] - w[0]).collect();
        let sigma = robust_noise_of_differences(&mut d);
        assert!((sigma / (q / 12f64.sqrt()) - 1.0).abs() < 1e-9, "{sigma}");
        // Gaussian noise of σ 0.5 by Box–Muller from a linear congruential sequence: σ within 5 %.
        let mut state = 12345u64;
        let mut uniform = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let noise: Vec<f64> = (0..20_000)
            .map(|_| 0.5 * (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos())
            .collect();
        let mut d: Vec<f64> = noise.windows(2).map(|w| w[1] - w[0]).collect();
        assert!((robust_noise_of_differences(&mut d) / 0.5 - 1.0).abs() < 0.05);
        assert_eq!(robust_noise_of_differences(&mut []), 0.0);
        assert_eq!(robust_noise_of_differences(&mut [0.0; 10]), 0.0, "a constant signal has no noise to read");
    }
}
