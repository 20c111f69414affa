//! The augmented model of a fitted structure, its simulated gap, the surface refined with it, and the
//! named effects' parameters and intervals.

use super::*;

/// The augmented model of a structure and its fit on `d` (its lateral axes, the speed its zero was read
/// at); `order` lists the accepted families in order.
pub(crate) fn to_model(
    base: &ContactModel,
    d: &Data,
    st: &Structure,
    fit: &Fit,
    order: &[(Family, f64)],
) -> ContactModel {
    let k = if fit.beta[0] > 0.0 { fit.beta[0] } else { base.stiffness };
    let mut m = base.clone();
    m.stiffness = k;
    m.damping = fit.beta[1].max(0.0);
    if (st.a - base.exponents.a).abs() > 1e-12 {
        m.kind = Kind::General;
        m.exponents = Exponents { a: st.a, b: st.b, c: st.c };
    }
    m.effects = order
        .iter()
        .filter_map(|&(f, sh)| {
            let b = |fam: Family| term_index(st, fam, sh).map_or(0.0, |j| fit.beta[j]);
            match f {
                Family::SensorBias => Some(Effect::SensorBias { offset: b(f) }),
                Family::SensorDrift => Some(Effect::SensorDrift { rate: b(f) }),
                Family::Relaxation => {
                    Some(Effect::ViscoelasticRelaxation { stiffness: b(f).max(0.0), time_constant: sh })
                }
                Family::Hysteresis => {
                    Some(Effect::Hysteresis { fraction: (b(f) / k).clamp(0.0, 0.999), velocity_scale: sh })
                }
                Family::OffsetDrift => Some(Effect::ContactOffsetDrift { rate: st.offset_rate }),
                Family::TimeDelay => Some(Effect::TimeDelay { delay: st.delay }),
                Family::Crosstalk => {
                    // A small rotation of the sensor: the coupling along each axis the record loads.
                    let along = |term: Term| st.terms.iter().position(|t| *t == term).map_or(0.0, |j| fit.beta[j + 2]);
                    let (u, v) = (d.lateral_axis.unwrap_or_default(), d.second_axis.unwrap_or_default());
                    let (b1, b2) = (along(Term::Crosstalk), along(Term::CrosstalkSecond));
                    Some(Effect::SensorCrosstalk { coupling: std::array::from_fn(|i| u[i] * b1 + v[i] * b2) })
                }
                Family::ToolGravity => Some(Effect::ToolGravity { mass: b(f) }),
                Family::Adhesion => Some(Effect::Adhesion { force: b(f).max(0.0), range: sh }),
                Family::QuasiLinear => {
                    Some(Effect::QuasiLinearRelaxation { fraction: (b(f) / k).max(0.0), time_constant: sh })
                }
                Family::MediumDrag => Some(Effect::MediumDrag { damping: b(f).max(0.0), tare_speed: d.tare_speed }),
                Family::SqueezeFilm => Some(Effect::SqueezeFilm { damping: b(f).max(0.0), reach: sh }),
                Family::StiffnessExponent => None,
            }
        })
        .collect();
    m
}

/// Samples in contact (z > 0) where `model`'s surface force is clamped at zero.
pub(crate) fn clamp_mask(model: &ContactModel, series: &Series) -> Result<Vec<bool>, DiscrepancyError> {
    Ok(steps(model, series)?.iter().zip(&series.z).map(|(&(surface, _), &z)| z > 0.0 && surface <= 0.0).collect())
}

/// In-contact RMS, per-phase RMS and lag-1 autocorrelation of the in-contact residual.
#[derive(Clone)]
pub(crate) struct Gap {
    pub(crate) rms: f64,
    /// RMS out of contact (0 without such samples).
    pub(crate) free_rms: f64,
    pub(crate) phases: BTreeMap<Phase, f64>,
    pub(crate) lag1: f64,
}

pub(crate) fn gap(series: &Series, phases: &[Phase], pred: &[f64]) -> Gap {
    let res: Vec<f64> = (0..series.len()).map(|i| series.f[i] - pred[i]).collect();
    let contact = |i: usize| phases[i].in_contact();
    let rms_of = |keep: &dyn Fn(usize) -> bool| -> Option<f64> {
        let (s, n) = (0..res.len()).filter(|&i| keep(i)).fold((0.0, 0usize), |(s, n), i| (s + res[i] * res[i], n + 1));
        (n > 0).then(|| (s / n as f64).sqrt())
    };
    let rms = rms_of(&contact).unwrap_or(0.0);
    let free_rms = rms_of(&|i| !contact(i)).unwrap_or(0.0);
    let phases_rms = Phase::ALL.iter().filter_map(|&p| rms_of(&|i| phases[i] == p).map(|r| (p, r))).collect();
    let (mut lag, mut ss) = (0.0, 0.0);
    for i in 0..res.len() {
        if contact(i) {
            ss += res[i] * res[i];
            if i > 0 && contact(i - 1) {
                lag += res[i] * res[i - 1];
            }
        }
    }
    Gap { rms, free_rms, phases: phases_rms, lag1: if ss > 0.0 { lag / ss } else { 0.0 } }
}

/// Refines the surface position (always) and its drift rate (when [`Term::OffsetLin`] is in the structure)
/// by Gauss-Newton on the exact law (z − z₀ − r·t)ᵃ: each fit's linearised coefficients k·δz₀ and k·δr are
/// moved into the structure until they vanish, and the samples where the law clamps re-masked at the moved
/// surface. Both linear columns stay in the structure, so that every later fit refits the position and the
/// drift jointly with its candidate. Returns the standard errors of z₀ and r too.
pub(crate) fn refine_surface(d: &Data, st: &Structure) -> (Structure, f64, f64) {
    let mut st = st.clone();
    if !st.terms.contains(&Term::Shift) {
        st.terms.insert(0, Term::Shift);
    }
    let start = st.clone();
    let (mut se_shift, mut se_rate) = (0.0, 0.0);
    let index = |st: &Structure, term: Term| st.terms.iter().position(|t| *t == term).map(|i| i + 2);
    for _ in 0..12 {
        let f = fit::fit(d, &st);
        let k = f.beta[0].abs().max(1e-300);
        let mut converged = true;
        if let Some(j) = index(&st, Term::Shift) {
            let delta = f.beta[j] / k;
            se_shift = f.se[j] / k;
            st.shift += delta;
            converged &= delta.abs() <= 1e-3 * se_shift.max(1e-12);
        }
        if let Some(j) = index(&st, Term::OffsetLin) {
            let delta = f.beta[j] / k;
            se_rate = f.se[j] / k;
            st.offset_rate += delta;
            converged &= delta.abs() <= 1e-4 * st.offset_rate.abs();
        }
        // Where the law clamps moves with the surface: a sample that enters contact during fast unloading
        // would otherwise be fitted with the pull the model clamps away.
        let mask = st.clamped.clone();
        st.remask(d, &f.beta);
        if converged && st.clamped == mask {
            break;
        }
    }
    // A surface the record does not pin down is not moved, and its column leaves the structure until a
    // later refinement (with more of the record explained) pins it down: a long hold after a short ramp
    // ran it 90 mm off on a 5 mm contact, and its free column made the law refitted beside it worse than
    // the one identified.
    if !crate::shift_identifiable(d.s, 1.96 * se_shift) {
        let mut placed = start;
        placed.terms.retain(|t| *t != Term::Shift);
        return (placed, se_shift, se_rate);
    }
    (st, se_shift, se_rate)
}

/// Half-widths (95 %) of a structure's parameters, keyed like the report.
pub(crate) fn uncertainty(
    d: &Data,
    st: &Structure,
    fit: &Fit,
    fam: Family,
    sh: f64,
    rate_se: f64,
) -> BTreeMap<String, f64> {
    let z = 1.96;
    let k = fit.beta[0].abs().max(1e-300);
    let mut u = BTreeMap::new();
    let shape_se = |term_of: &dyn Fn(f64) -> Term| -> f64 {
        // The Jacobian column of the fitted term with respect to its shape, added to the design.
        let j = term_index(st, fam, sh).unwrap_or(2);
        let eps = 1e-3;
        let col = |x: f64| {
            let mut s = st.clone();
            s.terms[j - 2] = term_of(x);
            fit::columns(d, &s).swap_remove(j)
        };
        let (up, dn) = (col(sh * (1.0 + eps)), col(sh * (1.0 - eps)));
        let jac = up.iter().zip(dn.iter()).map(|(a, b)| fit.beta[j] * (a - b) / (2.0 * eps * sh)).collect();
        let mut cols = fit::columns(d, st);
        cols.push(jac);
        let f = fit::fit_columns(d, &cols);
        f.se[f.se.len() - 1]
    };
    match fam {
        Family::SensorBias => {
            u.insert("offset_n".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)]);
        }
        Family::SensorDrift => {
            u.insert("rate_n_per_s".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)]);
        }
        Family::Relaxation => {
            u.insert("stiffness_n_per_m".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)]);
            u.insert("time_constant_s".into(), z * shape_se(&Term::Relax));
        }
        Family::Hysteresis => {
            u.insert("fraction".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)] / k);
            u.insert("velocity_scale_m_per_s".into(), z * shape_se(&Term::Hyst));
        }
        Family::StiffnessExponent => {
            let mut sd = st.clone();
            sd.terms.push(Term::ExpDeriv);
            let f = fit::fit(d, &sd);
            u.insert("exponent".into(), z * f.se[f.se.len() - 1] / f.beta[0].abs().max(1e-300));
        }
        Family::OffsetDrift => {
            u.insert("rate_m_per_s".into(), z * rate_se);
        }
        Family::TimeDelay => {
            let mut cols = fit::columns(d, st);
            cols.push(fit::negative_rate(&d.time, &fit.pred).into());
            let f = fit::fit_columns(d, &cols);
            u.insert("delay_s".into(), z * f.se[f.se.len() - 1]);
        }
        Family::Crosstalk => {
            let se = |term: Term| st.terms.iter().position(|t| *t == term).map_or(0.0, |j| fit.se[j + 2]);
            let (se1, se2) = (se(Term::Crosstalk), se(Term::CrosstalkSecond));
            for (i, axis) in ["coupling_x", "coupling_y", "coupling_z"].into_iter().enumerate() {
                let (a, b) = (d.lateral_axis.map_or(0.0, |a| a[i]), d.second_axis.map_or(0.0, |a| a[i]));
                u.insert(axis.into(), z * (se1 * a).hypot(se2 * b));
            }
        }
        Family::ToolGravity => {
            u.insert("mass_kg".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)]);
        }
        Family::QuasiLinear => {
            u.insert("fraction".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)] / k);
            u.insert("time_constant_s".into(), z * shape_se(&Term::QuasiRelax));
        }
        Family::MediumDrag => {
            u.insert("damping_n_s_per_m".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)]);
        }
        Family::SqueezeFilm => {
            u.insert("damping_n_s_per_m".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)]);
            u.insert("reach_m".into(), z * shape_se(&Term::Squeeze));
        }
        Family::Adhesion => {
            u.insert("force_n".into(), z * fit.se[term_index(st, fam, sh).unwrap_or(2)]);
            // Where it lets go is known to within the deformation's step across the letting go, however
            // sharp the fit's minimum.
            let step = let_go_steps(d, st, term_index(st, fam, sh).unwrap_or(2)).fold(0.0, f64::max);
            u.insert("range_m".into(), (z * shape_se(&Term::Adhesion)).max(step));
        }
    }
    u
}

/// Where the adhesion of column `j` lets go: the deformation's step across each letting go [m] (the pull
/// was on before the sample and is off at it, beyond the surface).
pub(crate) fn let_go_steps<'a>(d: &'a Data, st: &'a Structure, j: usize) -> impl Iterator<Item = f64> + 'a {
    let col = fit::columns(d, st).swap_remove(j);
    let zeff = move |i: usize| d.s.z[i] - st.shift - st.offset_rate * d.time[i];
    (1..col.len())
        .filter(move |&i| col[i - 1] != 0.0 && col[i] == 0.0 && zeff(i) < 0.0)
        .map(move |i| (zeff(i) - zeff(i - 1)).abs())
}

pub(crate) fn parameters(model: &ContactModel, fam: Family, shape: f64) -> BTreeMap<String, f64> {
    let mut p = BTreeMap::new();
    if fam == Family::StiffnessExponent {
        p.insert("exponent".into(), model.exponents.a);
        return p;
    }
    for e in &model.effects {
        match (*e, fam) {
            (Effect::SensorBias { offset }, Family::SensorBias) => {
                p.insert("offset_n".into(), offset);
            }
            (Effect::SensorDrift { rate }, Family::SensorDrift) => {
                p.insert("rate_n_per_s".into(), rate);
            }
            (Effect::ViscoelasticRelaxation { stiffness, time_constant }, Family::Relaxation)
                if time_constant == shape =>
            {
                p.insert("stiffness_n_per_m".into(), stiffness);
                p.insert("time_constant_s".into(), time_constant);
            }
            (Effect::Hysteresis { fraction, velocity_scale }, Family::Hysteresis) => {
                p.insert("fraction".into(), fraction);
                p.insert("velocity_scale_m_per_s".into(), velocity_scale);
            }
            (Effect::ContactOffsetDrift { rate }, Family::OffsetDrift) => {
                p.insert("rate_m_per_s".into(), rate);
            }
            (Effect::TimeDelay { delay }, Family::TimeDelay) => {
                p.insert("delay_s".into(), delay);
            }
            (Effect::SensorCrosstalk { coupling }, Family::Crosstalk) => {
                for (axis, c) in ["coupling_x", "coupling_y", "coupling_z"].into_iter().zip(coupling) {
                    p.insert(axis.into(), c);
                }
            }
            (Effect::ToolGravity { mass }, Family::ToolGravity) => {
                p.insert("mass_kg".into(), mass);
            }
            (Effect::QuasiLinearRelaxation { fraction, time_constant }, Family::QuasiLinear) => {
                p.insert("fraction".into(), fraction);
                p.insert("time_constant_s".into(), time_constant);
            }
            (Effect::Adhesion { force, range }, Family::Adhesion) => {
                p.insert("force_n".into(), force);
                p.insert("range_m".into(), range);
            }
            // Its tare speed is read from the record, not fitted: the model file carries it.
            (Effect::MediumDrag { damping, .. }, Family::MediumDrag) => {
                p.insert("damping_n_s_per_m".into(), damping);
            }
            (Effect::SqueezeFilm { damping, reach }, Family::SqueezeFilm) => {
                p.insert("damping_n_s_per_m".into(), damping);
                p.insert("reach_m".into(), reach);
            }
            _ => {}
        }
    }
    p
}
