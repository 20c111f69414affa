//! Golden-section search: the minimum of a unimodal function on an interval, without derivatives.

/// Golden-section minimum of `f` on [lo, hi].
pub(crate) fn golden(mut f: impl FnMut(f64) -> f64, mut lo: f64, mut hi: f64, iters: usize) -> f64 {
    let phi = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x1, mut x2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..iters {
        if f1 <= f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - phi * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + phi * (hi - lo);
            f2 = f(x2);
        }
    }
    if f1 <= f2 { x1 } else { x2 }
}
