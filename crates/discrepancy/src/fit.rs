//! The linear core: a model structure (base law plus augmentation terms with fixed shapes) becomes a design
//! matrix whose columns are scaled to unit RMS; least squares on it, blocked cross-validation from per-fold
//! Gram matrices, AICc, and standard errors inflated for residual autocorrelation.

use nalgebra::{DMatrix, DVector};
use std::collections::HashMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::ops::Range;
use std::sync::Arc;

use softcontact_contact::{ContactModel, adhesion_share, maxwell_step, maxwell_step_with_decay, next_adhesion_peak};

use crate::Series;
use crate::folds::{cells, contiguous_folds, interleaved_folds};
pub(crate) use crate::term::Term;

/// One column of the design, one value a sample; shared, so that a cached column is handed out without a copy (and a screen on another thread may hold one).
pub(crate) type Col = Arc<[f64]>;

/// Base law exponents a (fitted), b, c (of the baseline kind), the surface position's shift [m] and its drift
/// rate [m/s] (refined by Gauss-Newton on the exact law), plus the terms.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Structure {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub shift: f64,
    pub offset_rate: f64,
    /// The reading's delay [s]: every column is read at t − delay.
    pub delay: f64,
    pub terms: Vec<Term>,
    /// Crosstalk is fitted along both lateral axes (the record loads the hand both ways across the
    /// surface: [`Data::second_axis`]), else along the first alone.
    pub crosstalk_both_axes: bool,
    /// In contact but the law would pull (fast unloading of a shallow contact): [`ContactModel::step`]
    /// clamps the surface force to 0 there, so the contact columns are zeroed. Where that happens moves
    /// with the surface position: [`Structure::remask`] after moving it.
    pub clamped: Vec<bool>,
}

impl Structure {
    /// Re-masks the samples where the law clamps, with the surface force of coefficients `beta` (of this
    /// structure's columns; the linearised surface terms, whose content a Gauss-Newton step has just moved
    /// into the structure, left out).
    pub fn remask(&mut self, d: &Data, beta: &[f64]) {
        let undelayed = Structure { delay: 0.0, ..self.clone() };
        let raw = columns_masked(d, &undelayed, &vec![false; d.s.len()]);
        self.clamped = surface_clamped(&self.terms, &raw, beta, |t| matches!(t, Term::Shift | Term::OffsetLin));
    }
}

/// Samples in contact where the surface force Σ βⱼ·colⱼ over the surface columns (not the sensor's, nor
/// those `skip` names) is ≤ 0; `raw` unmasked and undelayed.
fn surface_clamped(terms: &[Term], raw: &[Col], beta: &[f64], skip: impl Fn(Term) -> bool) -> Vec<bool> {
    let surface = |j: usize| j < 2 || !(terms[j - 2].unclamped() || skip(terms[j - 2]));
    (0..raw[0].len())
        .map(|i| {
            raw[0][i] > 0.0 && (0..raw.len()).filter(|&j| surface(j)).map(|j| beta[j] * raw[j][i]).sum::<f64>() <= 0.0
        })
        .collect()
}

/// The series with what every fit needs precomputed.
pub(crate) struct Data<'a> {
    pub s: &'a Series,
    /// Time as [`softcontact_contact::ContactModel::step`] counts it: the sum of the dt handed to it.
    pub time: Vec<f64>,
    /// Time since the sensor's last tare, counted the same way.
    pub since_tare: Vec<f64>,
    pub dt: Vec<f64>,
    /// The record cut into contiguous cells: the free space before the first contact, the contact (from
    /// its first sample to its last) and the free space after it, each in 2·folds parts, the contact's
    /// with an equal share of the in-contact samples.
    pub cells: Vec<Range<usize>>,
    /// The folds the rules judge by, as cells: fold f holds part f and part f + folds of each region, one
    /// from the first half of the contact and one from the second ([`interleaved_folds`]).
    pub folds: Vec<Vec<usize>>,
    /// The folds rivals are judged by: contiguous in time ([`contiguous_folds`]).
    pub stretch_folds: Vec<Vec<usize>>,
    /// Σ f² over each cell.
    pub force_squares: Vec<f64>,
    /// Where the baseline law would pull (k zᵃ + λ zᵇ żᶜ < 0): the first structure's mask.
    pub clamped: Vec<bool>,
    /// The unit axis of the tangential force (its principal direction) and the force along it, when the
    /// series carries tangential force.
    pub lateral_axis: Option<[f64; 3]>,
    pub lateral: Vec<f64>,
    /// The axis across the first in the plane of the tangential forces (their second principal direction)
    /// and the force along it, where that force is a load, not noise: it varies in contact ten times as
    /// much as in free space (the rule of [`crate::lateral::loads`], as for the first).
    pub second_axis: Option<[f64; 3]>,
    pub second: Vec<f64>,
    /// The speed [m/s] where the sensor's zero was read ([`crate::drag::tare_speed`]), ż less it (a drag's
    /// column), and whether free space shows a drag ([`crate::drag::drag_observable`]).
    pub tare_speed: f64,
    pub drag_rate: Vec<f64>,
    pub drag_observable: bool,
    /// Columns already computed (see [`ColumnCache`]).
    pub cache: std::cell::RefCell<ColumnCache>,
    /// Their products (see [`ProductCache`]).
    pub products: std::cell::RefCell<ProductCache>,
}

impl<'a> Data<'a> {
    /// `tare_window` [s]: how long a tare reads the sensor before its time ([`crate::Options::tare_window`]).
    pub fn new(s: &'a Series, folds: usize, tare_window: f64, baseline: &ContactModel) -> Self {
        let n = s.len();
        let dt = crate::step_sizes(s);
        let mut time = Vec::with_capacity(n);
        let mut acc = 0.0;
        for &d in &dt {
            acc += d;
            time.push(acc);
        }
        let mut since = 0.0;
        let since_tare = dt
            .iter()
            .zip(s.tared_before())
            .map(|(&d, tared)| {
                since = if tared { d } else { since + d };
                since
            })
            .collect();
        let cells = cells(&s.t, &s.z, &s.zdot, folds);
        let force_squares = cells.iter().map(|r| dot(&s.f[r.clone()], &s.f[r.clone()])).collect();
        let (stretch_folds, folds) = (contiguous_folds(folds), interleaved_folds(folds));
        let clamped =
            (0..n).map(|i| s.z[i] > 0.0 && baseline.force(s.z[i], s.zdot[i]).is_ok_and(|f| f <= 0.0)).collect();
        let [lateral_axis, second_axis] = crate::lateral::principal_axes(&s.tangential);
        let along = |axis: Option<[f64; 3]>| match axis {
            Some(u) => s.tangential.iter().map(|f| f[0] * u[0] + f[1] * u[1] + f[2] * u[2]).collect(),
            None => Vec::new(),
        };
        let lateral = along(lateral_axis);
        let second = along(second_axis);
        let (second_axis, second) =
            if crate::lateral::loads(&s.z, &second) { (second_axis, second) } else { (None, Vec::new()) };
        let tare_speed = crate::drag::tare_speed(s, tare_window);
        let drag_rate = s.zdot.iter().map(|v| v - tare_speed).collect();
        Data {
            s,
            time,
            since_tare,
            dt,
            cells,
            folds,
            stretch_folds,
            force_squares,
            clamped,
            lateral_axis,
            lateral,
            second_axis,
            second,
            tare_speed,
            drag_rate,
            drag_observable: crate::drag::drag_observable(s),
            cache: Default::default(),
            products: Default::default(),
        }
    }
}

impl<'a> Data<'a> {
    /// The same series and precomputed vectors with empty caches, for a screen on another thread (the
    /// caches are transparent: a cached column or product is the same arithmetic as a fresh one).
    pub fn detached(&self) -> Data<'a> {
        Data {
            s: self.s,
            time: self.time.clone(),
            since_tare: self.since_tare.clone(),
            dt: self.dt.clone(),
            cells: self.cells.clone(),
            folds: self.folds.clone(),
            stretch_folds: self.stretch_folds.clone(),
            force_squares: self.force_squares.clone(),
            clamped: self.clamped.clone(),
            lateral_axis: self.lateral_axis,
            lateral: self.lateral.clone(),
            second_axis: self.second_axis,
            second: self.second.clone(),
            tare_speed: self.tare_speed,
            drag_rate: self.drag_rate.clone(),
            drag_observable: self.drag_observable,
            cache: Default::default(),
            products: Default::default(),
        }
    }
}

#[inline]
fn signed_pow(x: f64, c: f64) -> f64 {
    if c == 1.0 { x } else { x.signum() * x.abs().powf(c) }
}

#[inline]
fn pow(z: f64, e: f64) -> f64 {
    if e == 0.0 {
        1.0
    } else if e == 1.0 {
        z
    } else if e == 0.5 {
        z.sqrt()
    } else if e == 1.5 {
        z * z.sqrt()
    } else {
        z.powf(e)
    }
}

/// The raw (unscaled) columns of a structure: [zᵃ, zᵇ·sgn(ż)|ż|ᶜ, terms…], each zero out of contact
/// except the sensor terms.
pub(crate) fn columns(d: &Data, st: &Structure) -> Vec<Col> {
    columns_masked(d, st, &st.clamped)
}

/// A column of the design: the base law's two, or a term's.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Column {
    Elastic,
    Rate,
    Term(Term),
}

/// Columns already computed, unmasked, each with what it depends on besides its own shape (the exponents,
/// the surface position and drift), most recently used last: a screen tries a dozen shapes of one term on a
/// structure whose other columns stay the same, the exponent's screen leaves the branches alone, and a
/// delayed fit or a re-mask reads the same columns under other masks.
#[derive(Default)]
pub(crate) struct ColumnCache {
    columns: Vec<(Column, [f64; 5], Col)>,
    /// The columns as the design has them (masked and delayed), by [`ColumnId`], most recently used last.
    designed: Vec<(ColumnId, Col)>,
}

/// Designed columns a [`ColumnCache`] keeps (12 MB at 60 000 samples).
const DESIGNED_COLUMNS: usize = 24;

/// Dot products of the design's columns, by each column's identity ([`ColumnId`]): a screen fits a dozen
/// shapes of one term beside columns that stay the same, and only the new column's products are new.
/// Each product is the same sum, in the same order, as computed afresh.
#[derive(Default)]
pub(crate) struct ProductCache {
    /// Σ c² over all samples.
    norms: HashMap<ColumnId, f64>,
    /// Per fold: Σ cⱼ·cₖ (the pair ordered by id) and Σ cⱼ·f.
    products: HashMap<(ColumnId, ColumnId), Vec<f64>>,
    with_force: HashMap<ColumnId, Vec<f64>>,
}

/// Products a [`ProductCache`] keeps before it starts afresh (a few MB).
const CACHED_PRODUCTS: usize = 20_000;

/// What a design column is: what it is of (its [`Column`] and the key its content depends on, as
/// [`ColumnCache`] keys it), the mask it was zeroed with and the delay it is read with, hashed.
type ColumnId = u64;

fn column_id(id: Column, key: &[f64; 5], mask: u64, delay: f64) -> ColumnId {
    let mut h = DefaultHasher::new();
    match id {
        Column::Elastic => 0u8.hash(&mut h),
        Column::Rate => 1u8.hash(&mut h),
        Column::Term(t) => {
            2u8.hash(&mut h);
            format!("{t:?}").hash(&mut h);
        }
    }
    key.map(f64::to_bits).hash(&mut h);
    mask.hash(&mut h);
    delay.to_bits().hash(&mut h);
    h.finish()
}

/// A hash of a mask, packed 64 samples a word.
fn mask_hash(mask: &[bool]) -> u64 {
    let mut h = DefaultHasher::new();
    mask.len().hash(&mut h);
    for chunk in mask.chunks(64) {
        chunk.iter().enumerate().fold(0u64, |w, (i, &b)| w | (u64::from(b) << i)).hash(&mut h);
    }
    h.finish()
}

/// Columns a [`ColumnCache`] keeps (19 MB at 60 000 samples).
const CACHED_COLUMNS: usize = 40;

/// [`columns`] with the given samples masked where the law clamps (instead of the structure's).
fn columns_masked(d: &Data, st: &Structure, clamped: &[bool]) -> Vec<Col> {
    columns_with_ids(d, st, clamped).0
}

/// [`columns_masked`], and each column's identity.
fn columns_with_ids(d: &Data, st: &Structure, clamped: &[bool]) -> (Vec<Col>, Vec<ColumnId>) {
    let design = design_of(st, clamped);
    let mut zeff = None;
    let cols = design.iter().map(|&(id, key, column_id)| design_column(d, st, clamped, id, key, column_id, &mut zeff));
    (cols.collect(), design.iter().map(|x| x.2).collect())
}

/// The columns of a structure's design: each with the key its content depends on and its identity.
fn design_of(st: &Structure, clamped: &[bool]) -> Vec<(Column, [f64; 5], ColumnId)> {
    let mask = mask_hash(clamped);
    let wanted = [Column::Elastic, Column::Rate].into_iter().chain(st.terms.iter().map(|&t| Column::Term(t)));
    wanted
        .map(|id| {
            // What the column depends on: the surface (not the sensor's columns), and the exponent its
            // power of z has (the branches have none).
            let key = match id {
                Column::Term(Term::Relax(_) | Term::Adhesion(_) | Term::Squeeze(_)) => {
                    [0.0, 0.0, 0.0, st.shift, st.offset_rate]
                }
                Column::Term(t) if t.of_sensor() => [0.0; 5],
                Column::Term(Term::QuasiRelax(_)) => [st.a, 0.0, 0.0, st.shift, st.offset_rate],
                Column::Rate => [0.0, st.b, st.c, st.shift, st.offset_rate],
                _ => [st.a, 0.0, 0.0, st.shift, st.offset_rate],
            };
            (id, key, column_id(id, &key, mask, st.delay))
        })
        .collect()
}

/// One column of the design, masked where the law clamps (but a sensor's or an adhesion's) and delayed,
/// from the caches where it is there; `zeff` the effective deformation, computed once where needed.
fn design_column(
    d: &Data,
    st: &Structure,
    clamped: &[bool],
    id: Column,
    key: [f64; 5],
    column_id: ColumnId,
    zeff: &mut Option<Vec<f64>>,
) -> Col {
    let mut caches = d.cache.borrow_mut();
    let ColumnCache { columns: cache, designed } = &mut *caches;
    if let Some(i) = designed.iter().position(|(c, _)| *c == column_id) {
        let hit = designed.remove(i);
        let col = Arc::clone(&hit.1);
        designed.push(hit);
        return col;
    }
    let index = match cache.iter().position(|(c, k, _)| *c == id && *k == key) {
        Some(i) => {
            let hit = cache.remove(i);
            cache.push(hit);
            cache.len() - 1
        }
        None => {
            let zeff = zeff.get_or_insert_with(|| {
                (0..d.s.len()).map(|i| d.s.z[i] - st.shift - st.offset_rate * d.time[i]).collect()
            });
            if cache.len() >= CACHED_COLUMNS {
                cache.remove(0);
            }
            cache.push((id, key, column(d, st, zeff, id).into()));
            cache.len() - 1
        }
    };
    let unmasked = &cache[index].2;
    debug_assert_eq!(unmasked.len(), clamped.len(), "a mask of every sample");
    let mut col: Col = if matches!(id, Column::Term(t) if t.unclamped()) {
        Arc::clone(unmasked)
    } else {
        unmasked.iter().zip(clamped).map(|(&v, &c)| if c { 0.0 } else { v }).collect()
    };
    // The sensor reads everything late: clamped where the surface lets go, then delayed.
    if st.delay > 0.0 {
        col = delayed(&d.time, &col, st.delay).into();
    }
    if designed.len() >= DESIGNED_COLUMNS {
        designed.remove(0);
    }
    designed.push((column_id, Arc::clone(&col)));
    col
}

/// One unmasked column at the effective deformation `zeff`.
fn column(d: &Data, st: &Structure, zeff: &[f64], id: Column) -> Vec<f64> {
    let s = d.s;
    let n = s.len();
    // The smallest deformation used where a column has a negative power of z (a < 1 or ln z).
    let zmin = || 1e-3 * zeff.iter().cloned().fold(0.0, f64::max).max(1e-9);
    let t = match id {
        Column::Elastic => return zeff.iter().map(|&z| if z > 0.0 { pow(z, st.a) } else { 0.0 }).collect(),
        Column::Rate => {
            return (0..n)
                .map(|i| if zeff[i] > 0.0 { pow(zeff[i], st.b) * signed_pow(s.zdot[i], st.c) } else { 0.0 })
                .collect();
        }
        Column::Term(t) => t,
    };
    match t {
        Term::Bias => vec![1.0; n],
        Term::SensorDrift => d.since_tare.clone(),
        Term::Drag => d.drag_rate.clone(),
        Term::Squeeze(reach) => (0..n).map(|i| s.zdot[i] * reach / ((-zeff[i]).max(0.0) + reach)).collect(),
        Term::Relax(tau) | Term::QuasiRelax(tau) => {
            // The branch of unit stiffness, updated as ContactModel::step_surface updates it; a
            // quasi-linear one driven by zᵃ.
            let elastic = matches!(t, Term::QuasiRelax(_));
            let drive = |z: f64| if elastic { pow(z.max(0.0), st.a) } else { z.max(0.0) };
            let mut x = 0.0;
            // exp(−dt/τ) again only where the step changes (a steady rate: once).
            let mut last = (f64::NAN, 0.0);
            (0..n)
                .map(|i| {
                    if zeff[i] > 0.0 {
                        let before = if i == 0 { zeff[i] - s.zdot[i] * d.dt[i] } else { zeff[i - 1] };
                        let change = drive(zeff[i]) - drive(before);
                        x = if d.dt[i] > 0.0 {
                            if d.dt[i] != last.0 {
                                last = (d.dt[i], (-d.dt[i] / tau).exp());
                            }
                            maxwell_step_with_decay(x, change, d.dt[i], tau, last.1)
                        } else {
                            maxwell_step(x, change, 0.0, tau)
                        };
                    } else {
                        x = 0.0;
                    }
                    x
                })
                .collect()
        }
        Term::Adhesion(range) => {
            // As ContactModel::step_surface pulls: from the contact's deepest deformation, until δ
            // beyond the surface.
            let mut peak: Option<f64> = None;
            zeff.iter()
                .map(|&z| {
                    peak = next_adhesion_peak(peak, z, range);
                    peak.map_or(0.0, |p| -adhesion_share(p, z, range))
                })
                .collect()
        }
        Term::Hyst(v0) => {
            (0..n).map(|i| if zeff[i] > 0.0 { pow(zeff[i], st.a) * (s.zdot[i] / v0).tanh() } else { 0.0 }).collect()
        }
        Term::Shift => {
            let zmin = zmin();
            (0..n).map(|i| if zeff[i] > 0.0 { -st.a * pow(zeff[i].max(zmin), st.a - 1.0) } else { 0.0 }).collect()
        }
        Term::OffsetLin => {
            let zmin = zmin();
            (0..n)
                .map(|i| if zeff[i] > 0.0 { -d.time[i] * st.a * pow(zeff[i].max(zmin), st.a - 1.0) } else { 0.0 })
                .collect()
        }
        Term::ExpDeriv => {
            let zmin = zmin();
            (0..n).map(|i| if zeff[i] > 0.0 { pow(zeff[i], st.a) * zeff[i].max(zmin).ln() } else { 0.0 }).collect()
        }
        Term::Crosstalk if d.lateral.len() == n => d.lateral.clone(),
        Term::CrosstalkSecond if d.second.len() == n => d.second.clone(),
        Term::Gravity if s.gravity_change.len() == n => s.gravity_change.clone(),
        Term::Crosstalk | Term::CrosstalkSecond | Term::Gravity => vec![0.0; n],
    }
}

/// `x` read `delay` late: x(t − delay) by linear interpolation between samples (the first value before the
/// first sample), as [`ContactModel::sense`] delays a reading.
pub(crate) fn delayed(time: &[f64], x: &[f64], delay: f64) -> Vec<f64> {
    let mut j = 0;
    (0..x.len())
        .map(|i| {
            let target = time[i] - delay;
            while j + 1 < i && time[j + 1] <= target {
                j += 1;
            }
            if target <= time[j] || j + 1 > i {
                x[j]
            } else {
                x[j] + (x[j + 1] - x[j]) * (target - time[j]) / (time[j + 1] - time[j])
            }
        })
        .collect()
}

/// −dx/dt by central differences (one-sided at the ends): the linearised change of x read δ later is
/// δ·(−ẋ).
pub(crate) fn negative_rate(time: &[f64], x: &[f64]) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            if b > a { -(x[b] - x[a]) / (time[b] - time[a]) } else { 0.0 }
        })
        .collect()
}

/// A least-squares fit with its held-out and in-sample scores.
#[derive(Debug, Clone)]
pub(crate) struct Fit {
    /// Coefficients of the raw columns (physical units).
    pub beta: Vec<f64>,
    /// Standard errors of `beta`, inflated by (1+ρ)/(1−ρ) for the lag-1 autocorrelation ρ of the residual.
    pub se: Vec<f64>,
    /// Coefficients fitted with each fold held out.
    pub fold_beta: Vec<Vec<f64>>,
    pub sse: f64,
    /// Mean held-out squared error over the interleaved folds [N²] ([`interleaved_folds`]).
    pub cv_mse: f64,
    /// Mean held-out squared error over the folds contiguous in time [N²] ([`contiguous_folds`]); NaN in
    /// a fit that only ranks shapes.
    pub stretch_mse: f64,
    pub aicc: f64,
    /// Fitted prediction at every sample [N].
    pub pred: Vec<f64>,
}

fn solve(g: &DMatrix<f64>, h: &DVector<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let p = g.nrows();
    let ridge = 1e-12 * (0..p).map(|i| g[(i, i)]).sum::<f64>().max(1e-300);
    let gr = g + DMatrix::identity(p, p) * ridge;
    match gr.clone().cholesky() {
        Some(ch) => (ch.solve(h), ch.inverse()),
        None => {
            let inv = gr.pseudo_inverse(1e-12).unwrap_or_else(|_| DMatrix::zeros(p, p));
            (&inv * h, inv)
        }
    }
}

/// Fits `y` on the given raw columns.
/// Σ aᵢbᵢ over equal-length slices, in four lanes so that it vectorises.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut lanes = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..4 {
            lanes[l] += x[l] * y[l];
        }
    }
    lanes.iter().sum::<f64>() + tail
}

pub(crate) fn fit_columns(d: &Data, cols: &[Col]) -> Fit {
    fit_columns_held_out(d, cols, None, None)
}

/// The squared held-out residual of every sample: each predicted by the fit with its fold left out.
pub(crate) fn held_out(d: &Data, st: &Structure) -> Vec<f64> {
    let mut out = vec![0.0; d.s.len()];
    let cols = columns(d, st);
    if st.delay <= 0.0 {
        fit_columns_held_out(d, &cols, None, Some(&mut out));
        return out;
    }
    // As `fit` does for a delay: masked with the delayed fit's own surface force.
    let fitted = fit(d, st);
    let undelayed = Structure { delay: 0.0, ..st.clone() };
    let raw = columns_masked(d, &undelayed, &vec![false; d.s.len()]);
    let mask = surface_clamped(&st.terms, &raw, &fitted.beta, |_| false);
    fit_columns_held_out(d, &columns_masked(d, st, &mask), None, Some(&mut out));
    out
}

/// The columns' dot products: Σ c² over all samples per column, and per cell Σ cⱼ·cₖ and Σ cⱼ·f (from the
/// cache where the columns' identities are given).
struct Products {
    norms: Vec<f64>,
    /// `pairs[j][k]` for k ≤ j, per cell.
    pairs: Vec<Vec<Vec<f64>>>,
    with_force: Vec<Vec<f64>>,
}

fn products(d: &Data, cols: &[Col], ids: Option<&[ColumnId]>) -> Products {
    let y = &d.s.f;
    let per_fold =
        |a: &[f64], b: &[f64]| -> Vec<f64> { d.cells.iter().map(|r| dot(&a[r.clone()], &b[r.clone()])).collect() };
    let Some(ids) = ids else {
        let p = cols.len();
        return Products {
            norms: cols.iter().map(|c| dot(c, c)).collect(),
            pairs: (0..p).map(|j| (0..=j).map(|k| per_fold(&cols[j], &cols[k])).collect()).collect(),
            with_force: cols.iter().map(|c| per_fold(c, y)).collect(),
        };
    };
    let p = ids.len();
    let mut cache = d.products.borrow_mut();
    let norms = (0..p).map(|j| *cache.norms.entry(ids[j]).or_insert_with(|| dot(&cols[j], &cols[j]))).collect();
    let pairs = (0..p)
        .map(|j| {
            (0..=j)
                .map(|k| {
                    let key = (ids[j].min(ids[k]), ids[j].max(ids[k]));
                    cache.products.entry(key).or_insert_with(|| per_fold(&cols[j], &cols[k])).clone()
                })
                .collect()
        })
        .collect();
    let with_force =
        (0..p).map(|j| cache.with_force.entry(ids[j]).or_insert_with(|| per_fold(&cols[j], y)).clone()).collect();
    Products { norms, pairs, with_force }
}

/// How much of a [`Fit`] to compute: a screen ranks shapes by the held-out MSE alone.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Extent {
    Full,
    /// The coefficients and the held-out MSE; no in-sample residual, standard errors, AICc or per-fold
    /// coefficients (left empty or NaN; never returned outside this file).
    HeldOutOnly,
}

fn fit_columns_held_out(d: &Data, cols: &[Col], ids: Option<&[ColumnId]>, per_sample: Option<&mut Vec<f64>>) -> Fit {
    fit_columns_to(d, cols, ids, per_sample, Extent::Full)
}

fn fit_columns_to(
    d: &Data,
    cols: &[Col],
    ids: Option<&[ColumnId]>,
    mut per_sample: Option<&mut Vec<f64>>,
    extent: Extent,
) -> Fit {
    let y = &d.s.f;
    let n = y.len();
    let p = ids.map_or(cols.len(), |ids| ids.len());
    let products = products(d, cols, ids);
    let scale: Vec<f64> = products
        .norms
        .iter()
        .map(|&c2| {
            let r = (c2 / n as f64).sqrt();
            if r > 0.0 && r.is_finite() { r } else { 1.0 }
        })
        .collect();
    // Per-fold Gram matrices, sums of the cells' column dot products.
    let gram = |fold: &[usize]| {
        let mut g = DMatrix::<f64>::zeros(p, p);
        let mut h = DVector::<f64>::zeros(p);
        for j in 0..p {
            h[j] = fold.iter().map(|&c| products.with_force[j][c]).sum::<f64>() / scale[j];
            for k in 0..=j {
                let v = fold.iter().map(|&c| products.pairs[j][k][c]).sum::<f64>() / (scale[j] * scale[k]);
                g[(j, k)] = v;
                g[(k, j)] = v;
            }
        }
        (g, h, fold.iter().map(|&c| d.force_squares[c]).sum::<f64>())
    };
    let per_fold: Vec<_> = d.folds.iter().map(|f| gram(f)).collect();
    let g: DMatrix<f64> = per_fold.iter().fold(DMatrix::zeros(p, p), |a, b| a + &b.0);
    let h: DVector<f64> = per_fold.iter().fold(DVector::zeros(p), |a, b| a + &b.1);
    let (beta_s, inv) = solve(&g, &h);
    let nf = n as f64;
    // The fold's held-out squared error and the coefficients fitted without it.
    let held_out_fold = |(gf, hf, yy): &(DMatrix<f64>, DVector<f64>, f64)| {
        let (bf, _) = solve(&(&g - gf), &(&h - hf));
        ((yy - 2.0 * bf.dot(hf) + (gf * &bf).dot(&bf)).max(0.0), bf)
    };
    if extent == Extent::HeldOutOnly {
        let held: f64 = per_fold.iter().map(|f| held_out_fold(f).0).sum();
        let beta = (0..p).map(|j| beta_s[j] / scale[j]).collect();
        return Fit {
            beta,
            se: vec![],
            fold_beta: vec![],
            sse: f64::NAN,
            cv_mse: held / nf,
            stretch_mse: f64::NAN,
            aicc: f64::NAN,
            pred: vec![],
        };
    }
    let mut pred = vec![0.0; n];
    for (j, c) in cols.iter().enumerate() {
        let b = beta_s[j] / scale[j];
        for i in 0..n {
            pred[i] += b * c[i];
        }
    }
    let res: Vec<f64> = (0..n).map(|i| y[i] - pred[i]).collect();
    let sse: f64 = res.iter().map(|r| r * r).sum();
    let lag: f64 = res.windows(2).map(|w| w[0] * w[1]).sum();
    let rho = if sse > 0.0 { lag / sse } else { 0.0 };
    let rc = rho.clamp(0.0, 0.999);
    let inflation = (1.0 + rc) / (1.0 - rc);
    let s2 = sse / (n.saturating_sub(p).max(1)) as f64;
    let se = (0..p).map(|j| (s2 * inflation * inv[(j, j)]).max(0.0).sqrt() / scale[j]).collect();
    let mut fold_beta = Vec::new();
    let mut held = 0.0;
    for (f, fold) in per_fold.iter().enumerate() {
        let (out, bf) = held_out_fold(fold);
        held += out;
        if let Some(res) = per_sample.as_deref_mut() {
            for i in d.folds[f].iter().flat_map(|&c| d.cells[c].clone()) {
                let p: f64 = (0..p).map(|j| bf[j] / scale[j] * cols[j][i]).sum();
                res[i] = (y[i] - p).powi(2);
            }
        }
        fold_beta.push((0..p).map(|j| bf[j] / scale[j]).collect());
    }
    let stretch: f64 = d.stretch_folds.iter().map(|f| held_out_fold(&gram(f)).0).sum();
    let pf = p as f64;
    let aicc = nf * (sse.max(1e-300) / nf).ln() + 2.0 * pf + 2.0 * pf * (pf + 1.0) / (nf - pf - 1.0).max(1.0);
    let beta = (0..p).map(|j| beta_s[j] / scale[j]).collect();
    Fit { beta, se, fold_beta, sse, cv_mse: held / nf, stretch_mse: stretch / nf, aicc, pred }
}

pub(crate) fn fit(d: &Data, st: &Structure) -> Fit {
    fit_to(d, st, Extent::Full)
}

/// The held-out MSE of a structure's fit (what a screen ranks shapes by), without the rest of [`fit`].
pub(crate) fn held_out_mse(d: &Data, st: &Structure) -> f64 {
    fit_to(d, st, Extent::HeldOutOnly).cv_mse
}

fn fit_to(d: &Data, st: &Structure, extent: Extent) -> Fit {
    let fit_structure_columns = |clamped: &[bool]| {
        let design = design_of(st, clamped);
        let ids: Vec<ColumnId> = design.iter().map(|x| x.2).collect();
        let mut products = d.products.borrow_mut();
        if products.products.len() > CACHED_PRODUCTS {
            *products = ProductCache::default();
        }
        // Held-out scores need a column only where one of its products is not known yet.
        let needed = |j: usize| {
            extent == Extent::Full
                || !products.norms.contains_key(&ids[j])
                || !products.with_force.contains_key(&ids[j])
                || ids.iter().any(|&k| !products.products.contains_key(&(ids[j].min(k), ids[j].max(k))))
        };
        let needed: Vec<bool> = (0..ids.len()).map(needed).collect();
        drop(products);
        let mut zeff = None;
        let cols: Vec<Col> = design
            .iter()
            .zip(&needed)
            .map(|(&(id, key, column_id), &needed)| match needed {
                true => design_column(d, st, clamped, id, key, column_id, &mut zeff),
                false => Arc::from([]),
            })
            .collect();
        fit_columns_to(d, &cols, Some(&ids), None, extent)
    };
    let fitted = fit_structure_columns(&st.clamped);
    if st.delay <= 0.0 {
        return fitted;
    }
    // Read late, the law clamps where its own undelayed surface force is ≤ 0 — which the mask of the
    // undelayed fit (where the refit damping may be negative and never clamps) gets wrong at every
    // lift-off: mask with this fit's own surface force, twice.
    let undelayed = Structure { delay: 0.0, ..st.clone() };
    let raw = columns_masked(d, &undelayed, &vec![false; d.s.len()]);
    let mut fitted = fitted;
    for _ in 0..2 {
        let mask = surface_clamped(&st.terms, &raw, &fitted.beta, |_| false);
        fitted = fit_structure_columns(&mask);
    }
    fitted
}
