//! Latency statistics for the 1 kHz paths: a fixed-bin histogram allocated once at start-up, so
//! recording a value costs an add and never allocates.

/// Values in [0, bins·width) fall in bins of `width`; larger ones count as overflow, and the maximum is
/// kept exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    width: f64,
    counts: Vec<u64>,
    overflow: u64,
    total: u64,
    max: f64,
}

impl Histogram {
    pub fn new(width: f64, bins: usize) -> Self {
        assert!(width > 0.0 && bins > 0, "a histogram needs a positive bin width and at least one bin");
        Self { width, counts: vec![0; bins], overflow: 0, total: 0, max: 0.0 }
    }

    /// Records one value (negative values count as 0, NaN as overflow).
    pub fn record(&mut self, value: f64) {
        let v = value.max(0.0);
        let bin = (v / self.width) as usize;
        match self.counts.get_mut(bin) {
            Some(c) if v.is_finite() => *c += 1,
            _ => self.overflow += 1,
        }
        self.total += 1;
        if v > self.max || value.is_nan() {
            self.max = if value.is_nan() { f64::INFINITY } else { v };
        }
    }

    pub fn count(&self) -> u64 {
        self.total
    }

    pub fn max(&self) -> f64 {
        self.max
    }

    /// Fraction of values not above `limit` (bins entirely below it).
    pub fn fraction_within(&self, limit: f64) -> f64 {
        if self.total == 0 {
            return 1.0;
        }
        let full = ((limit / self.width).floor() as usize).min(self.counts.len());
        self.counts[..full].iter().sum::<u64>() as f64 / self.total as f64
    }

    /// The upper edge of the bin holding quantile `p` (a bound, never an underestimate), or the maximum
    /// when it lies in the overflow.
    pub fn quantile(&self, p: f64) -> f64 {
        if self.total == 0 {
            return 0.0;
        }
        let rank = ((p.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return ((i + 1) as f64 * self.width).min(self.max);
            }
        }
        self.max
    }

    /// `p50 … p99 … p99.9 … max` in the unit `scale` turns values into, for exit reports.
    pub fn summary(&self, scale: f64, unit: &str) -> String {
        format!(
            "n {} p50 {:.3} p99 {:.3} p99.9 {:.3} max {:.3} {unit}",
            self.total,
            self.quantile(0.5) * scale,
            self.quantile(0.99) * scale,
            self.quantile(0.999) * scale,
            self.max * scale
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_bound_the_exact_ones_from_above_within_a_bin() {
        let mut h = Histogram::new(1e-6, 1000);
        let values: Vec<f64> = (0..10_000).map(|i| ((i * 7919) % 10_000) as f64 * 1e-7).collect();
        for v in &values {
            h.record(*v);
        }
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        for p in [0.5, 0.99, 0.999] {
            let exact = sorted[(p * sorted.len() as f64).ceil() as usize - 1];
            let q = h.quantile(p);
            assert!(q >= exact && q <= exact + 1e-6 + 1e-12, "p{p}: {q} vs {exact}");
        }
        assert_eq!(h.count(), 10_000);
        assert!((h.max() - 9.999e-4).abs() < 1e-12);
        assert!((h.fraction_within(5e-4) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn overflow_and_nan_count_and_raise_the_maximum() {
        let mut h = Histogram::new(1.0, 10);
        h.record(3.5);
        h.record(50.0);
        assert_eq!(h.quantile(1.0), 50.0);
        assert_eq!(h.fraction_within(10.0), 0.5);
        h.record(f64::NAN);
        assert_eq!(h.max(), f64::INFINITY);
        assert_eq!(h.count(), 3);
    }
}
