//! The sliding-window estimator: the last N samples (the force-control paper: 1200 at 10 ms), O(1) work per sample,
//! and a full cross-validated refit of every candidate kind on demand.

use std::collections::VecDeque;

use crate::ContactError;
use crate::fit::{Fit, FitConfig, Moments, Prior, Sample, fit_folds, fold_of, regressors};
use crate::model::Kind;

/// Every candidate kind fitted to the same samples, and the one chosen.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// One fit per candidate kind, in [`Kind::CANDIDATES`] order.
    pub fits: Vec<Fit>,
    /// The kind with the highest cross-validated fitness.
    pub selected: Kind,
}

impl Estimate {
    /// Chooses the best cross-validated fitness among fits (NaN fitness never wins).
    pub fn choose(fits: Vec<Fit>) -> Result<Self, ContactError> {
        let selected = fits
            .iter()
            .filter(|f| f.fitness_mean.is_finite())
            .max_by(|a, b| a.fitness_mean.total_cmp(&b.fitness_mean))
            .map(|f| f.kind)
            .ok_or(ContactError::NotEnoughData { kind: "any candidate" })?;
        Ok(Self { fits, selected })
    }

    pub fn fit(&self, kind: Kind) -> Option<&Fit> {
        self.fits.iter().find(|f| f.kind == kind)
    }

    pub fn selected_fit(&self) -> &Fit {
        self.fit(self.selected).expect("the selected kind has a fit")
    }
}

/// Fits every candidate kind to samples in time order, with cross-validated fitness, and chooses one.
pub fn estimate(samples: &[Sample], priors: &[Prior; 3], cfg: &FitConfig) -> Result<Estimate, ContactError> {
    let fits = Kind::CANDIDATES
        .iter()
        .zip(priors)
        .map(|(&kind, prior)| crate::fit::fit(kind, kind.exponents().expect("named kind"), samples, *prior, cfg))
        .collect::<Result<Vec<_>, _>>()?;
    Estimate::choose(fits)
}

/// Regressors of the three candidate kinds for one sample.
type Columns = [(f64, f64); 3];

fn columns(s: &Sample) -> Columns {
    Kind::CANDIDATES.map(|k| regressors(&k.exponents().expect("named kind"), s.z, s.zdot))
}

/// Sliding window of the last `capacity` samples with running least-squares moments of every
/// candidate kind. Running sums drift by rounding as samples come and go, so they are recomputed
/// exactly from the stored regressors once per `capacity` samples (amortised O(1)).
#[derive(Debug, Clone)]
pub struct WindowEstimator {
    capacity: usize,
    /// (time [s] or NaN when pushed without one, sample, its regressors).
    samples: VecDeque<(f64, Sample, Columns)>,
    moments: [Moments; 3],
    since_resync: usize,
    config: FitConfig,
    priors: [Prior; 3],
}

impl WindowEstimator {
    pub fn new(capacity: usize, config: FitConfig) -> Result<Self, ContactError> {
        if capacity < 2 * config.folds || config.folds < 2 {
            return Err(ContactError::InvalidConfig(format!(
                "window of {capacity} samples cannot hold {} folds of 2 samples",
                config.folds
            )));
        }
        Ok(Self {
            capacity,
            samples: VecDeque::with_capacity(capacity),
            moments: [Moments::default(); 3],
            since_resync: 0,
            config,
            priors: [None; 3],
        })
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    pub fn is_full(&self) -> bool {
        self.samples.len() == self.capacity
    }

    /// Samples, oldest first.
    pub fn samples(&self) -> impl Iterator<Item = &Sample> {
        self.samples.iter().map(|(_, s, _)| s)
    }

    /// Samples with their times, oldest first (NaN for a sample pushed without one).
    pub fn timed_samples(&self) -> impl Iterator<Item = crate::TimedSample> + '_ {
        self.samples.iter().map(|&(t, sample, _)| crate::TimedSample { t, sample })
    }

    pub fn clear(&mut self) {
        self.samples.clear();
        self.moments = [Moments::default(); 3];
        self.since_resync = 0;
    }

    /// Prior (k, λ) of a kind, used where the window does not determine a parameter.
    pub fn set_prior(&mut self, kind: Kind, stiffness: f64, damping: f64) {
        if let Some(i) = Kind::CANDIDATES.iter().position(|&k| k == kind) {
            self.priors[i] = Some((stiffness, damping));
        }
    }

    /// Adds a sample, dropping the oldest when full. O(1); a non-finite sample is refused.
    pub fn push(&mut self, sample: Sample) -> Result<(), ContactError> {
        self.push_at(f64::NAN, sample)
    }

    /// [`WindowEstimator::push`] with the sample's time \[s\] (a fit with named effects needs it).
    pub fn push_at(&mut self, t: f64, sample: Sample) -> Result<(), ContactError> {
        let sample = Sample::new(sample.z, sample.zdot, sample.f)?;
        if self.samples.len() == self.capacity
            && let Some((_, old, cols)) = self.samples.pop_front()
        {
            for (m, (x1, x2)) in self.moments.iter_mut().zip(cols) {
                m.remove(x1, x2, old.f);
            }
        }
        let cols = columns(&sample);
        for (m, (x1, x2)) in self.moments.iter_mut().zip(cols) {
            m.add(x1, x2, sample.f, 1.0);
        }
        self.samples.push_back((t, sample, cols));
        self.since_resync += 1;
        if self.since_resync >= self.capacity {
            self.resync();
        }
        Ok(())
    }

    /// Recomputes the running moments exactly from the stored regressors.
    fn resync(&mut self) {
        self.moments = [Moments::default(); 3];
        for (_, s, cols) in &self.samples {
            for (m, (x1, x2)) in self.moments.iter_mut().zip(cols) {
                m.add(*x1, *x2, s.f, 1.0);
            }
        }
        self.since_resync = 0;
    }

    /// Running least-squares moments of a candidate kind.
    pub fn moments(&self, kind: Kind) -> Option<&Moments> {
        Kind::CANDIDATES.iter().position(|&k| k == kind).map(|i| &self.moments[i])
    }

    /// The current unconstrained least-squares (k, λ) of a candidate kind, in O(1).
    pub fn current(&self, kind: Kind) -> Option<(f64, f64)> {
        self.moments(kind)?.solve()
    }

    /// Full refit of every candidate kind over the window, with cross-validated fitness and the
    /// excitation guard; parameters the window determines become the priors of the next refit.
    pub fn refit(&mut self) -> Result<Estimate, ContactError> {
        let folds = self.config.folds;
        let n = self.samples.len();
        if n < 2 * folds {
            return Err(ContactError::NotEnoughData { kind: "window" });
        }
        let mut fold_moments = vec![[Moments::default(); 3]; folds];
        for (i, (_, s, cols)) in self.samples.iter().enumerate() {
            let fold = fold_of(i, n, folds);
            for (m, (x1, x2)) in fold_moments[fold].iter_mut().zip(cols) {
                m.add(*x1, *x2, s.f, 1.0);
            }
        }
        let mut fits = Vec::with_capacity(3);
        for (i, kind) in Kind::CANDIDATES.into_iter().enumerate() {
            let per_fold: Vec<Moments> = fold_moments.iter().map(|f| f[i]).collect();
            let fit = fit_folds(kind, kind.exponents().expect("named kind"), &per_fold, self.priors[i], &self.config)?;
            let prior = self.priors[i].unwrap_or((fit.stiffness, fit.damping));
            self.priors[i] = Some((
                if fit.stiffness_held { prior.0 } else { fit.stiffness },
                if fit.damping_held { prior.1 } else { fit.damping },
            ));
            fits.push(fit);
        }
        Estimate::choose(fits)
    }
}
