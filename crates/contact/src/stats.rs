//! Fit statistics exactly as the snake paper's Appendix defines them (its Tables I–III).

use crate::ContactError;

/// The snake paper's Appendix C: how well a model's predictions f_m fit measured forces f_d.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitStatistics {
    /// R² "as reported by Mathematica" for a nonlinear model fit: 1 − Σ(f_d − f_m)² / Σ f_d², with the
    /// uncorrected total sum of squares (NonlinearModelFit does not subtract the mean).
    pub r_squared: f64,
    /// (1/n) Σ |f_d − f_m| \[N\].
    pub mean_abs_error: f64,
    /// (1/n) Σ |(f_d − f_m) / f_m| over the samples where the model predicts a non-zero force.
    pub mean_normalized_abs_error: f64,
    /// max (f_d − f_m) \[N\].
    pub max_error: f64,
    /// min (f_d − f_m) \[N\].
    pub min_error: f64,
    pub samples: usize,
}

/// Statistics of predictions against measurements (equal lengths, finite values).
pub fn fit_statistics(measured: &[f64], predicted: &[f64]) -> Result<FitStatistics, ContactError> {
    if measured.len() != predicted.len() || measured.is_empty() {
        return Err(ContactError::InvalidConfig(format!(
            "statistics need equally long, non-empty series (got {} and {})",
            measured.len(),
            predicted.len()
        )));
    }
    if let Some(v) = measured.iter().chain(predicted).find(|v| !v.is_finite()) {
        return Err(ContactError::NonFinite { name: "force", value: *v });
    }
    let n = measured.len() as f64;
    let errors: Vec<f64> = measured.iter().zip(predicted).map(|(d, m)| d - m).collect();
    let sse: f64 = errors.iter().map(|e| e * e).sum();
    let total: f64 = measured.iter().map(|d| d * d).sum();
    let normalized: Vec<f64> =
        errors.iter().zip(predicted).filter(|(_, m)| **m != 0.0).map(|(e, m)| (e / m).abs()).collect();
    Ok(FitStatistics {
        r_squared: if total > 0.0 { 1.0 - sse / total } else { f64::NAN },
        mean_abs_error: errors.iter().map(|e| e.abs()).sum::<f64>() / n,
        mean_normalized_abs_error: if normalized.is_empty() {
            f64::NAN
        } else {
            normalized.iter().sum::<f64>() / normalized.len() as f64
        },
        max_error: errors.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        min_error: errors.iter().copied().fold(f64::INFINITY, f64::min),
        samples: measured.len(),
    })
}

/// The snake paper's Appendix D: spread of (normal, tangential) forces measured at loading-path convergence
/// points, where a path-independent model must predict one force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dispersion {
    /// Σ_j Σ_i ‖(f_n, f_t)_ij − μ_j‖ \[N\].
    pub total_error: f64,
    /// (1/n) Σ_j Σ_i ‖(f_n, f_t)_ij − μ_j‖ / ‖μ_j‖, n the number of points.
    pub mean_normalized_error: f64,
}

/// Dispersion of the points of each convergence point (one inner slice per point).
pub fn dispersion(points: &[Vec<(f64, f64)>]) -> Result<Dispersion, ContactError> {
    let mut total = 0.0;
    let mut normalized = 0.0;
    let mut n = 0usize;
    for group in points {
        if group.is_empty() {
            return Err(ContactError::InvalidConfig("a convergence point has no data".into()));
        }
        if let Some(v) = group.iter().flat_map(|(a, b)| [*a, *b]).find(|v| !v.is_finite()) {
            return Err(ContactError::NonFinite { name: "force", value: v });
        }
        let m = group.len() as f64;
        let mean = (group.iter().map(|p| p.0).sum::<f64>() / m, group.iter().map(|p| p.1).sum::<f64>() / m);
        let mean_norm = mean.0.hypot(mean.1);
        for p in group {
            let d = (p.0 - mean.0).hypot(p.1 - mean.1);
            total += d;
            normalized += d / mean_norm;
        }
        n += group.len();
    }
    if n == 0 {
        return Err(ContactError::InvalidConfig("no convergence points".into()));
    }
    Ok(Dispersion { total_error: total, mean_normalized_error: normalized / n as f64 })
}
