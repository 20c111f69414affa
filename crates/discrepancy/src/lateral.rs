//! The tangential load's axes: along which directions of the surface's plane a record loads the hand, the
//! excitation a sensor's crosstalk needs (`fit::Data::lateral_axis`, `fit::Data::second_axis`).

/// The principal directions of the tangential forces: u₁ with the largest Σ(F_t·u)², the leading
/// eigenvector of Σ F_t F_tᵀ, and u₂ the second; each with its largest component made positive; `None`
/// without tangential force (u₂: without force across u₁).
pub(crate) fn principal_axes(forces: &[[f64; 3]]) -> [Option<[f64; 3]>; 2] {
    let m = forces.iter().fold(nalgebra::Matrix3::<f64>::zeros(), |m, f| {
        let v = nalgebra::Vector3::from(*f);
        m + v * v.transpose()
    });
    if m.trace().is_nan() || m.trace() <= 0.0 {
        return [None, None];
    }
    let eigen = nalgebra::SymmetricEigen::new(m);
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| eigen.eigenvalues[j].total_cmp(&eigen.eigenvalues[i]));
    let axis = |k: usize| {
        let u = eigen.eigenvectors.column(order[k]).into_owned();
        let u = if u[u.iamax()] < 0.0 { -u } else { u };
        (eigen.eigenvalues[order[k]] > 0.0).then_some([u.x, u.y, u.z])
    };
    [axis(0), axis(1)]
}

/// Whether a tangential force `along` an axis is a load: in contact (z > 0) it varies ten times as much
/// as out of contact, where it is the sensor's noise and drift.
pub(crate) fn loads(z: &[f64], along: &[f64]) -> bool {
    let spread = |keep: &dyn Fn(usize) -> bool| {
        let v: Vec<f64> = (0..along.len()).filter(|&i| keep(i)).map(|i| along[i]).collect();
        let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    !along.is_empty()
        && along.iter().any(|v| *v != along[0])
        && spread(&|i| z[i] > 0.0) > 10.0 * spread(&|i| z[i] <= 0.0)
}
