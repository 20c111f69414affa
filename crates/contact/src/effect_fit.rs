//! The window refitted with named effects: the structure the discrepancy workflow found (its kind,
//! exponents, relaxation time constants, hysteresis velocity scale) is kept, and every amplitude is
//! fitted again to the latest samples, with where the surface lies.
//!
//! For a fixed structure the force is linear in its amplitudes:
//!
//! f = k z^a + λ z^b sgn(ż)|ż|^c + (k h) z^a tanh(ż/v₀) + Σᵢ kᵢ rᵢ(t) + Σᵢ sᵢ₀ e^{−(t−t₀)/τᵢ} − F_a u(t) + b
//!
//! where rᵢ is the Maxwell branch ṙ = ż − r/τᵢ driven by the samples' own deformation (the force of a
//! branch of unit stiffness; [`maxwell_step`], the model's own step), restarted at zero where the window
//! has a gap (the contact was left: its samples are in contact only), sᵢ₀ the branch force the window
//! starts with (a quasi-linear branch's rᵢ is driven by zᵃ instead, its amplitude g·k), u the share of an adhesion's pull-off force F_a (its range fixed; the window's deepest
//! deformation its peak), and b the sensor's offset now (its bias and the drift since the tare, as one constant
//! over the window). The named drags of the medium ([`Effect::MediumDrag`], [`Effect::SqueezeFilm`]) are
//! held as named and taken from each reading first: in contact a drag is one more damping, which only free
//! space (not in the window) tells from λ, and fitted beside λ it would be counted twice. Least squares by QR; an amplitude fitted unphysical (λ, kᵢ < 0, h outside [0, 1)) is
//! fixed at zero and the rest fitted again. The surface is placed by a golden-section search of the
//! residual over the offset range, as [`crate::estimate_contact_offset`] does for the base law.

use faer::Mat;
use faer::linalg::solvers::SolveLstsq;

use crate::ContactError;
use crate::exponent::minimize_scalar;
use crate::fit::Sample;
use crate::model::{ContactModel, Effect, adhesion_share, maxwell_step, pow};

/// A window sample with its time \[s\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedSample {
    pub t: f64,
    pub sample: Sample,
}

/// The fewest samples the fit takes.
pub const MIN_EFFECT_SAMPLES: usize = 50;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Column {
    Elastic,
    Rate,
    Hysteresis {
        velocity_scale: f64,
    },
    /// A branch of unit stiffness driven by the deformation (`elastic`: by zᵃ, a quasi-linear branch).
    Branch {
        index: usize,
        time_constant: f64,
        elastic: bool,
    },
    BranchStart {
        time_constant: f64,
    },
    Adhesion {
        range: f64,
    },
    Bias,
}

/// The columns of the structure: the base law, then its effects in order.
fn columns(structure: &ContactModel) -> Vec<Column> {
    let mut cols = vec![Column::Elastic, Column::Rate];
    let mut bias = false;
    for (index, e) in structure.effects.iter().enumerate() {
        match *e {
            Effect::Hysteresis { velocity_scale, .. } => cols.push(Column::Hysteresis { velocity_scale }),
            Effect::ViscoelasticRelaxation { time_constant, .. } => {
                cols.push(Column::Branch { index, time_constant, elastic: false });
                cols.push(Column::BranchStart { time_constant });
            }
            Effect::QuasiLinearRelaxation { time_constant, .. } => {
                cols.push(Column::Branch { index, time_constant, elastic: true });
                cols.push(Column::BranchStart { time_constant });
            }
            Effect::SensorBias { .. } | Effect::SensorDrift { .. } => bias = true,
            Effect::Adhesion { range, .. } => cols.push(Column::Adhesion { range }),
            _ => {}
        }
    }
    if bias {
        cols.push(Column::Bias);
    }
    cols
}

/// The design matrix of `cols` for the samples with the surface `offset` deeper than their zero.
fn design(samples: &[TimedSample], cols: &[Column], structure: &ContactModel, offset: f64) -> Mat<f64> {
    let n = samples.len();
    let e = structure.exponents;
    let mut a = Mat::<f64>::zeros(n, cols.len());
    for (j, col) in cols.iter().enumerate() {
        match *col {
            Column::Branch { time_constant, elastic, .. } => {
                // Through a gap too (the force was below the onset threshold, the surface may still be
                // pressed): the change over it, the decay of its length.
                let drive = |z: f64| if elastic { pow(z.max(0.0), e.a) } else { z.max(0.0) };
                let mut r = 0.0;
                for i in 1..n {
                    let change = drive(samples[i].sample.z - offset) - drive(samples[i - 1].sample.z - offset);
                    r = maxwell_step(r, change, samples[i].t - samples[i - 1].t, time_constant);
                    a[(i, j)] = r;
                }
            }
            Column::Adhesion { range } => {
                // Minus the share of the pull-off force (the model's own pull), the contact's deepest
                // deformation counted from the window's start.
                let mut peak = f64::NEG_INFINITY;
                for i in 0..n {
                    let z = samples[i].sample.z - offset;
                    peak = peak.max(z);
                    if z >= -range && peak > 0.0 {
                        a[(i, j)] = -adhesion_share(peak, z, range);
                    }
                }
            }
            Column::BranchStart { time_constant } => {
                for i in 0..n {
                    a[(i, j)] = (-(samples[i].t - samples[0].t) / time_constant).exp();
                }
            }
            _ => {
                for i in 0..n {
                    let s = samples[i].sample;
                    let z = s.z - offset;
                    if z <= 0.0 && *col != Column::Bias {
                        continue;
                    }
                    a[(i, j)] = match *col {
                        Column::Elastic => pow(z, e.a),
                        Column::Rate => pow(z, e.b) * s.zdot.signum() * s.zdot.abs().powf(e.c),
                        Column::Hysteresis { velocity_scale } => pow(z, e.a) * (s.zdot / velocity_scale).tanh(),
                        _ => 1.0,
                    };
                }
            }
        }
    }
    a
}

/// What the structure's named drags add to the reading of sample `s` with the surface `offset` deeper than
/// its zero, as [`ContactModel::sense`] adds them.
fn named_drag(structure: &ContactModel, s: &Sample, offset: f64) -> f64 {
    structure.effects.iter().map(|e| e.drag(s.zdot, (offset - s.z).max(0.0))).sum()
}

/// Least squares over the columns not fixed at zero; returns the amplitudes (zero where fixed) and the
/// residual sum of squares.
fn solve(a: &Mat<f64>, f: &Mat<f64>, free: &[bool]) -> Option<(Vec<f64>, f64)> {
    let idx: Vec<usize> = (0..free.len()).filter(|&j| free[j]).collect();
    let sub = Mat::from_fn(a.nrows(), idx.len(), |i, j| a[(i, idx[j])]);
    // Columns scaled to unit norm: the branch and elastic columns differ by orders of magnitude.
    let norms: Vec<f64> =
        (0..idx.len()).map(|j| (0..sub.nrows()).map(|i| sub[(i, j)].powi(2)).sum::<f64>().sqrt().max(1e-300)).collect();
    let scaled = Mat::from_fn(sub.nrows(), idx.len(), |i, j| sub[(i, j)] / norms[j]);
    let x = scaled.qr().solve_lstsq(f);
    let mut amplitudes = vec![0.0_f64; free.len()];
    for (j, &c) in idx.iter().enumerate() {
        amplitudes[c] = x[(j, 0)] / norms[j];
    }
    if amplitudes.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let rss = (0..a.nrows())
        .map(|i| {
            let predicted: f64 = (0..free.len()).map(|j| a[(i, j)] * amplitudes[j]).sum();
            (f[(i, 0)] - predicted).powi(2)
        })
        .sum();
    Some((amplitudes, rss))
}

/// The fit at one offset: unphysical amplitudes fixed at zero one at a time, the worst first.
fn fit_at(
    samples: &[TimedSample],
    cols: &[Column],
    structure: &ContactModel,
    offset: f64,
) -> Option<(Vec<f64>, Vec<bool>, f64)> {
    let a = design(samples, cols, structure, offset);
    let f =
        Mat::from_fn(samples.len(), 1, |i, _| samples[i].sample.f - named_drag(structure, &samples[i].sample, offset));
    let mut free = vec![true; cols.len()];
    loop {
        let (x, rss) = solve(&a, &f, &free)?;
        let k = x[0];
        let badness = |j: usize| -> f64 {
            match cols[j] {
                Column::Rate | Column::Branch { .. } | Column::Adhesion { .. } => -x[j],
                Column::Hysteresis { .. } if k > 0.0 => (-x[j]).max(x[j] / k - 0.999),
                _ => f64::NEG_INFINITY,
            }
        };
        match (0..cols.len())
            .filter(|&j| free[j] && badness(j) > 0.0)
            .max_by(|&i, &j| badness(i).total_cmp(&badness(j)))
        {
            Some(j) => free[j] = false,
            None => return Some((x, free, rss)),
        }
    }
}

/// Refits the amplitudes of `structure` (a model with named effects) to `samples` (in time order, in
/// contact, deformation from the onset position) and places the surface within `offset_range` of the
/// onset \[m\]. Returns the offset and the model: the structure's effects in their order with the new
/// amplitudes, the sensor's bias and drift replaced by the offset the window reads now
/// (`sensor_bias`), any other effect as named.
///
/// With a sensor offset fitted, the surface's place and the offset trade against each other (for a
/// linear law exactly: k(z − δ) = kz − kδ) unless the window leaves the surface; hold the surface where
/// it is known instead ([`fit_with_effects_at`]).
pub fn fit_with_effects(
    samples: &[TimedSample],
    structure: &ContactModel,
    offset_range: (f64, f64),
) -> Result<(f64, ContactModel), ContactError> {
    check(samples, structure)?;
    let (lo, hi) = offset_range;
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(ContactError::InvalidConfig("offset range must satisfy lo < hi".into()));
    }
    let cols = columns(structure);
    let rss = |offset: f64| fit_at(samples, &cols, structure, offset).map_or(f64::INFINITY, |(_, _, r)| r);
    let (offset, _, _) = minimize_scalar(rss, lo, hi, 20, 1e-7);
    Ok((offset, fit_with_effects_at(samples, structure, offset)?))
}

/// [`fit_with_effects`] with the surface held `offset` \[m\] below the onset position.
pub fn fit_with_effects_at(
    samples: &[TimedSample],
    structure: &ContactModel,
    offset: f64,
) -> Result<ContactModel, ContactError> {
    check(samples, structure)?;
    if !offset.is_finite() {
        return Err(ContactError::NonFinite { name: "offset", value: offset });
    }
    let cols = columns(structure);
    let (x, _, _) = fit_at(samples, &cols, structure, offset)
        .ok_or(ContactError::NotEnoughData { kind: "the window with named effects" })?;
    let k = x[0];
    if k.is_nan() || k <= 0.0 {
        return Err(ContactError::NotEnoughData { kind: "the window with named effects: stiffness" });
    }
    let mut model = structure.clone();
    model.stiffness = k;
    model.damping = x[1];
    let amplitude = |pick: &dyn Fn(&Column) -> bool| cols.iter().position(pick).map(|j| x[j]);
    let bias = amplitude(&|c| *c == Column::Bias);
    let mut effects = Vec::with_capacity(model.effects.len());
    let mut bias_placed = false;
    for (index, e) in model.effects.iter().enumerate() {
        effects.push(match *e {
            Effect::ViscoelasticRelaxation { time_constant, .. } => Effect::ViscoelasticRelaxation {
                stiffness: amplitude(&|c| matches!(c, Column::Branch { index: i, .. } if *i == index)).unwrap_or(0.0),
                time_constant,
            },
            Effect::QuasiLinearRelaxation { time_constant, .. } => Effect::QuasiLinearRelaxation {
                fraction: amplitude(&|c| matches!(c, Column::Branch { index: i, .. } if *i == index)).unwrap_or(0.0)
                    / k,
                time_constant,
            },
            Effect::Hysteresis { velocity_scale, .. } => Effect::Hysteresis {
                fraction: amplitude(&|c| matches!(c, Column::Hysteresis { .. })).unwrap_or(0.0) / k,
                velocity_scale,
            },
            Effect::Adhesion { range, .. } => Effect::Adhesion {
                force: amplitude(&|c| *c == Column::Adhesion { range }).unwrap_or(0.0).max(0.0),
                range,
            },
            Effect::SensorBias { .. } | Effect::SensorDrift { .. } if !bias_placed => {
                bias_placed = true;
                Effect::SensorBias { offset: bias.unwrap_or(0.0) }
            }
            Effect::SensorBias { .. } | Effect::SensorDrift { .. } => continue,
            other => other,
        });
    }
    model.effects = effects;
    model.validate()?;
    Ok(model)
}

fn check(samples: &[TimedSample], structure: &ContactModel) -> Result<(), ContactError> {
    structure.validate()?;
    if samples.len() < MIN_EFFECT_SAMPLES {
        return Err(ContactError::NotEnoughData { kind: "the window with named effects" });
    }
    if samples.iter().any(|s| !s.t.is_finite()) || samples.windows(2).any(|w| w[1].t <= w[0].t) {
        return Err(ContactError::InvalidConfig("window samples need increasing, finite times".into()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Kind;

    /// The sponge of the simulated cell: Azad–Featherstone with two relaxation branches and hysteresis,
    /// read by a sensor 0.7 N high; sampled at 10 ms along pushes (the model's own stepping at 1 ms is the
    /// truth here, and the fit sees only the 10 ms samples).
    fn truth() -> ContactModel {
        let mut m = ContactModel::new(Kind::AzadFeatherstone, 25_000.0, 1100.0).unwrap();
        m.effects = vec![
            Effect::ViscoelasticRelaxation { stiffness: 2500.0, time_constant: 0.15 },
            Effect::ViscoelasticRelaxation { stiffness: 100.0, time_constant: 5.0 },
            Effect::Hysteresis { fraction: 0.02, velocity_scale: 0.05 },
            Effect::SensorBias { offset: 0.7 },
        ];
        m
    }

    fn record(model: &ContactModel, surface: f64, seconds: f64) -> Vec<TimedSample> {
        record_from(model, surface, seconds, 1.0)
    }

    /// [`record`] keeping the samples after `from` [s].
    fn record_from(model: &ContactModel, surface: f64, seconds: f64, from: f64) -> Vec<TimedSample> {
        let mut state = model.effect_state();
        let mut out = Vec::new();
        let dt = 1e-3;
        for i in 0..(seconds / dt) as usize {
            let t = i as f64 * dt;
            // Pushes between 2 and 5 cm at 0.5 Hz, a hold of 2 s every 6 s.
            let hold = (t % 6.0) > 4.0;
            let phase = if hold { 0.0 } else { t % 6.0 };
            let w = std::f64::consts::PI;
            let depth = 0.035 + 0.015 * (w * phase).sin();
            let rate = if hold { 0.0 } else { 0.015 * w * (w * phase).cos() };
            let (_, read) = model.step(&mut state, depth, rate, dt).unwrap();
            // In contact only, as the estimator keeps them (a quick unloading lifts off before z = 0).
            if i % 10 == 0 && t > from && read > 1.0 {
                out.push(TimedSample { t, sample: Sample { z: depth + surface, zdot: rate, f: read } });
            }
        }
        out
    }

    #[test]
    fn the_amplitudes_and_the_surface_come_back_with_the_time_constants_given() {
        let truth = truth();
        // The window's zero is 2 mm above the surface (the onset fired early).
        let samples = record(&truth, 0.002, 13.0);
        assert!(samples.len() >= 1199, "{} samples: none may lift off", samples.len());
        let mut structure = truth.clone();
        structure.stiffness = 30_000.0;
        structure.damping = 2500.0;
        for e in &mut structure.effects {
            match e {
                Effect::ViscoelasticRelaxation { stiffness, .. } => *stiffness = 1.0,
                Effect::Hysteresis { fraction, .. } => *fraction = 0.1,
                Effect::SensorBias { offset } => *offset = 0.0,
                _ => {}
            }
        }
        let (offset, fitted) = fit_with_effects(&samples, &structure, (-0.01, 0.01)).unwrap();
        assert!((offset - 0.002).abs() < 1e-6, "offset {offset}");
        // Held where it is, the same.
        assert_eq!(fit_with_effects_at(&samples, &structure, offset).unwrap(), fitted);
        let close = |a: f64, b: f64, tol: f64| (a / b - 1.0).abs() < tol;
        assert!(close(fitted.stiffness, 25_000.0, 1e-3), "{}", fitted.stiffness);
        assert!(close(fitted.damping, 1100.0, 1e-2), "{}", fitted.damping);
        for (got, want) in fitted.effects.iter().zip(&truth.effects) {
            match (got, want) {
                (
                    Effect::ViscoelasticRelaxation { stiffness: a, .. },
                    Effect::ViscoelasticRelaxation { stiffness: b, .. },
                ) => assert!(close(*a, *b, 0.02), "branch {a} for {b}"),
                (Effect::Hysteresis { fraction: a, .. }, Effect::Hysteresis { fraction: b, .. }) => {
                    assert!(close(*a, *b, 0.02), "hysteresis {a} for {b}")
                }
                (Effect::SensorBias { offset: a }, Effect::SensorBias { offset: b }) => {
                    assert!((a - b).abs() < 0.01, "bias {a} for {b}")
                }
                other => panic!("effects out of order: {other:?}"),
            }
        }
    }

    /// A named drag of the medium or of a squeeze film is held and taken from the readings: λ comes back
    /// as the surface's own, not with the drag in it, and the drag stays as named.
    #[test]
    fn a_named_drag_is_held_and_not_counted_into_the_damping_again() {
        for drag in [
            Effect::MediumDrag { damping: 800.0, tare_speed: 0.0 },
            Effect::SqueezeFilm { damping: 800.0, reach: 0.004 },
        ] {
            let mut truth = ContactModel::new(Kind::KelvinVoigt, 25_000.0, 300.0).unwrap();
            truth.effects = vec![drag];
            let samples = record(&truth, 0.0, 13.0);
            let structure = ContactModel { stiffness: 30_000.0, damping: 0.0, ..truth.clone() };
            let fitted = fit_with_effects_at(&samples, &structure, 0.0).unwrap();
            assert!((fitted.damping / 300.0 - 1.0).abs() < 1e-3, "{drag:?}: λ {}", fitted.damping);
            assert!((fitted.stiffness / 25_000.0 - 1.0).abs() < 1e-3, "{drag:?}: k {}", fitted.stiffness);
            assert_eq!(fitted.effects, [drag]);
        }
    }

    #[test]
    fn an_adhesions_pull_off_force_comes_back_with_its_range_given() {
        let mut truth = ContactModel::new(Kind::AzadFeatherstone, 25_000.0, 1100.0).unwrap();
        truth.effects = vec![Effect::Adhesion { force: 3.0, range: 0.003 }];
        // From before the first peak: the window's deepest deformation is the contact's.
        let samples = record_from(&truth, 0.0, 13.0, 0.3);
        let mut structure = truth.clone();
        structure.effects = vec![Effect::Adhesion { force: 0.0, range: 0.003 }];
        let (offset, fitted) = fit_with_effects(&samples, &structure, (-0.01, 0.01)).unwrap();
        let Effect::Adhesion { force, range } = fitted.effects[0] else { panic!() };
        assert!((force - 3.0).abs() < 0.03 && range == 0.003, "pull-off {force} N for 3 N");
        assert!(offset.abs() < 1e-6, "offset {offset}");
        // A surface that does not hold on: no pull, not a push.
        let samples = record_from(&ContactModel { effects: vec![], ..truth }, 0.0, 13.0, 0.3);
        let (_, fitted) = fit_with_effects(&samples, &structure, (-0.01, 0.01)).unwrap();
        let Effect::Adhesion { force, .. } = fitted.effects[0] else { panic!() };
        assert!((0.0..0.03).contains(&force), "no adhesion fitted as {force} N");
    }

    #[test]
    fn a_quasi_linear_fraction_comes_back_with_its_time_constant_given() {
        let mut truth = ContactModel::new(Kind::AzadFeatherstone, 25_000.0, 1100.0).unwrap();
        truth.effects = vec![Effect::QuasiLinearRelaxation { fraction: 0.12, time_constant: 0.4 }];
        let samples = record(&truth, 0.0, 13.0);
        let mut structure = truth.clone();
        structure.effects = vec![Effect::QuasiLinearRelaxation { fraction: 0.0, time_constant: 0.4 }];
        let (_, fitted) = fit_with_effects(&samples, &structure, (-0.01, 0.01)).unwrap();
        let Effect::QuasiLinearRelaxation { fraction, time_constant } = fitted.effects[0] else { panic!() };
        assert!((fraction / 0.12 - 1.0).abs() < 0.02 && time_constant == 0.4, "fraction {fraction} for 0.12");
        assert!((fitted.stiffness / 25_000.0 - 1.0).abs() < 1e-2, "{}", fitted.stiffness);
    }

    #[test]
    fn a_branch_the_samples_do_not_show_is_fixed_at_zero_not_negative() {
        let mut truth = truth();
        truth.effects.truncate(1);
        truth.effects[0] = Effect::ViscoelasticRelaxation { stiffness: 2500.0, time_constant: 0.15 };
        let samples = record(&truth, 0.0, 13.0);
        let mut structure = truth.clone();
        // A named slow branch the truth does not have.
        structure.effects.push(Effect::ViscoelasticRelaxation { stiffness: 100.0, time_constant: 5.0 });
        let (_, fitted) = fit_with_effects(&samples, &structure, (-0.01, 0.01)).unwrap();
        let Effect::ViscoelasticRelaxation { stiffness, .. } = fitted.effects[1] else { panic!() };
        assert!((0.0..5.0).contains(&stiffness), "absent branch fitted at {stiffness} N/m");
    }

    #[test]
    fn bad_windows_are_refused() {
        let samples = record(&truth(), 0.0, 3.0);
        assert!(fit_with_effects(&samples[..10], &truth(), (-0.01, 0.01)).is_err());
        let mut backwards = samples.clone();
        backwards.swap(3, 4);
        assert!(fit_with_effects(&backwards, &truth(), (-0.01, 0.01)).is_err());
        assert!(fit_with_effects(&samples, &truth(), (0.01, -0.01)).is_err());
        let mut nan = samples;
        nan[5].t = f64::NAN;
        assert!(fit_with_effects(&nan, &truth(), (-0.01, 0.01)).is_err());
    }
}
