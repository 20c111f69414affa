//! The snake paper's statistics against values published elsewhere and worked by hand.

use faer::Mat;
use faer::linalg::solvers::SolveLstsq;
use softcontact_contact::{dispersion, fit_statistics};

/// Mathematica's NonlinearModelFit on this data and a·x² + b·x + c reports RSquared 0.963173 (the
/// uncorrected total sum of squares), where the centred definition gives 0.762242.
#[test]
fn r_squared_is_mathematicas() {
    let data: [(f64, f64); 12] = [
        (-0.582258428, 0.49531889),
        (-2.475512593, 0.751434565),
        (-1.508540016, 0.571212292),
        (2.004747546, 0.187621117),
        (1.139972167, 0.297735572),
        (-0.724053077, 0.457858443),
        (-0.830992757, 0.313642502),
        (-3.830561204, 0.81639874),
        (-2.357296433, 0.804397821),
        (0.986610836, 0.221932888),
        (-0.513640368, 0.704999208),
        (-1.508540016, 0.798426867),
    ];
    let a = Mat::from_fn(data.len(), 3, |i, j| data[i].0.powi(2 - j as i32));
    let y = Mat::from_fn(data.len(), 1, |i, _| data[i].1);
    let p = a.qr().solve_lstsq(&y);
    let fitted: Vec<f64> = data.iter().map(|(x, _)| p[(0, 0)] * x * x + p[(1, 0)] * x + p[(2, 0)]).collect();
    let measured: Vec<f64> = data.iter().map(|d| d.1).collect();
    let s = fit_statistics(&measured, &fitted).unwrap();
    assert!((s.r_squared - 0.963173).abs() < 5e-7, "R² {}", s.r_squared);
}

#[test]
fn error_statistics_follow_the_appendix() {
    let measured = [10.0, 21.0, 29.0, 42.0];
    let model = [10.0, 20.0, 30.0, 40.0];
    let s = fit_statistics(&measured, &model).unwrap();
    assert_eq!(s.mean_abs_error, (0.0 + 1.0 + 1.0 + 2.0) / 4.0);
    assert!((s.mean_normalized_abs_error - (0.0 + 0.05 + 1.0 / 30.0 + 0.05) / 4.0).abs() < 1e-15);
    assert_eq!((s.max_error, s.min_error), (2.0, -1.0));
    assert!((s.r_squared - (1.0 - 6.0 / (100.0 + 441.0 + 841.0 + 1764.0))).abs() < 1e-15);
    assert!(fit_statistics(&measured, &model[..3]).is_err());
    assert!(fit_statistics(&[f64::NAN], &[1.0]).is_err());
}

#[test]
fn dispersion_follows_the_appendix() {
    // Two convergence points: (3, 4) ± (1, 0) and (0, 10) exactly.
    let points = vec![vec![(2.0, 4.0), (4.0, 4.0)], vec![(0.0, 10.0), (0.0, 10.0), (0.0, 10.0)]];
    let d = dispersion(&points).unwrap();
    assert_eq!(d.total_error, 2.0);
    assert!((d.mean_normalized_error - (1.0 / 5.0 + 1.0 / 5.0) / 5.0).abs() < 1e-15);
    assert!(dispersion(&[vec![]]).is_err());
}
