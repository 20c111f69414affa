//! The library of effects as the workflow screens them: each family's id, term, shape grid and what
//! would tell two of them apart.

use super::*;

/// A candidate family of the library.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Family {
    SensorBias,
    SensorDrift,
    Relaxation,
    Hysteresis,
    StiffnessExponent,
    OffsetDrift,
    TimeDelay,
    Crosstalk,
    ToolGravity,
    Adhesion,
    QuasiLinear,
    MediumDrag,
    SqueezeFilm,
}

impl Family {
    pub(crate) const ALL: [Family; 13] = [
        Family::SensorBias,
        Family::SensorDrift,
        Family::Relaxation,
        Family::Hysteresis,
        Family::StiffnessExponent,
        Family::OffsetDrift,
        Family::TimeDelay,
        Family::Crosstalk,
        Family::ToolGravity,
        Family::Adhesion,
        Family::QuasiLinear,
        Family::MediumDrag,
        Family::SqueezeFilm,
    ];

    pub(crate) fn id(self) -> &'static str {
        match self {
            Family::SensorBias => "sensor_bias",
            Family::SensorDrift => "sensor_drift",
            Family::Relaxation => "viscoelastic_relaxation",
            Family::Hysteresis => "hysteresis",
            Family::StiffnessExponent => "stiffness_exponent",
            Family::OffsetDrift => "contact_offset_drift",
            Family::TimeDelay => "time_delay",
            Family::Crosstalk => "sensor_crosstalk",
            Family::ToolGravity => "tool_gravity",
            Family::Adhesion => "adhesion",
            Family::QuasiLinear => "quasi_linear_relaxation",
            Family::MediumDrag => "medium_drag",
            Family::SqueezeFilm => "squeeze_film",
        }
    }

    /// A form of the surface's own dissipation: what closes a loading–unloading loop.
    pub(crate) fn dissipative(self) -> bool {
        matches!(self, Family::Relaxation | Family::QuasiLinear | Family::Hysteresis)
    }

    /// Whether the series can show this family at all: crosstalk needs tangential force, the tool's
    /// weight a change of orientation, a moving surface zero contact that recurs or lasts.
    pub(crate) fn observable(self, d: &Data) -> bool {
        match self {
            // A tangential load: the tangential force in contact varies well beyond the sensor's own
            // tangential noise and drift in free space (ten times).
            Family::Crosstalk => crate::lateral::loads(&d.s.z, &d.lateral),
            // A tilt: gravity along the normal changes by at least 0.05 m/s² (a tilt of about 6° from the
            // tare's orientation); the hand's wobble under an impedance shows nothing of its weight.
            Family::ToolGravity => {
                let g = &d.s.gravity_change;
                let (lo, hi) = g.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
                !g.is_empty() && hi - lo >= MIN_GRAVITY_CHANGE
            }
            // The hand leaves a contact: only beyond the surface does a pull tell itself from a loop.
            Family::Adhesion => {
                let first = d.s.z.iter().position(|&z| z > 0.0);
                first.is_some_and(|i| d.s.z[i..].iter().any(|&z| z <= 0.0))
            }
            // A surface zero moving linearly in time: within one short contact its only trace is an offset
            // between loading and unloading, which the surface's own loop makes too. A candidate where
            // contact recurs (two contacts or more) or lasts (half the record), so that the zero is seen
            // moving across contact.
            Family::OffsetDrift => {
                let contacts =
                    d.s.z
                        .chunk_by(|a, b| (*a > 0.0) == (*b > 0.0))
                        .filter(|run| run[0] > 0.0 && run.len() >= MIN_CONTACT_SAMPLES);
                let in_contact = d.s.z.iter().filter(|&&z| z > 0.0).count();
                contacts.count() >= 2 || 2 * in_contact >= d.s.z.len()
            }
            // The hand moving through the medium out of contact: in contact a drag is one more damping.
            // A squeeze film the same way, near the surface.
            Family::MediumDrag | Family::SqueezeFilm => d.drag_observable,
            _ => true,
        }
    }

    /// The term this family adds (None for the exponent, which changes a, and the delay, which reads every
    /// column late).
    pub(crate) fn term(self, shape: f64) -> Option<Term> {
        match self {
            Family::Crosstalk => Some(Term::Crosstalk),
            Family::ToolGravity => Some(Term::Gravity),
            Family::TimeDelay => None,
            Family::SensorBias => Some(Term::Bias),
            Family::SensorDrift => Some(Term::SensorDrift),
            Family::Relaxation => Some(Term::Relax(shape)),
            Family::Hysteresis => Some(Term::Hyst(shape)),
            Family::Adhesion => Some(Term::Adhesion(shape)),
            Family::QuasiLinear => Some(Term::QuasiRelax(shape)),
            Family::MediumDrag => Some(Term::Drag),
            Family::SqueezeFilm => Some(Term::Squeeze(shape)),
            Family::OffsetDrift => Some(Term::OffsetLin),
            Family::StiffnessExponent => None,
        }
    }

    /// The structure without this family's term (None for the exponent, which has no term to remove).
    pub(crate) fn remove(self, st: &Structure, shape: f64) -> Option<Structure> {
        if self == Family::TimeDelay {
            return Some(Structure { delay: 0.0, ..st.clone() });
        }
        let term = self.term(shape)?;
        let mut st = st.clone();
        st.terms.retain(|t| *t != term && !(term == Term::Crosstalk && *t == Term::CrosstalkSecond));
        if self == Family::OffsetDrift {
            st.offset_rate = 0.0;
        }
        Some(st)
    }

    pub(crate) fn apply(self, st: &Structure, shape: f64) -> Structure {
        let mut st = st.clone();
        match self.term(shape) {
            Some(Term::Crosstalk) if st.crosstalk_both_axes => {
                st.terms.extend([Term::Crosstalk, Term::CrosstalkSecond])
            }
            Some(t) => st.terms.push(t),
            None if self == Family::TimeDelay => st.delay = shape,
            None => st.a = shape,
        }
        st
    }

    /// Shape grid: τ over the record's [`Scales::time_constants`] (log; a second branch at least 3× from
    /// the first), v₀ 1–100 % of the 95th-percentile speed (log), a′ 0.8–2.5, delays over
    /// [`Scales::delays`] (log).
    pub(crate) fn grid(self, scales: &Scales, st: &Structure) -> Vec<f64> {
        let a = st.a;
        let log = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
            (0..n).map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64)).collect()
        };
        match self {
            Family::Relaxation => scales
                .time_constant_grid()
                .into_iter()
                .filter(|&tau| {
                    st.terms.iter().all(|t| !matches!(*t, Term::Relax(other) if (tau / other).ln().abs() < 3f64.ln()))
                })
                .collect(),
            Family::Hysteresis => log(0.01 * scales.p95_speed, scales.p95_speed, 9),
            Family::StiffnessExponent => {
                (0..=17).map(|i| EXPONENT_RANGE.0 + 0.1 * i as f64).filter(|x| (x - a).abs() > 0.049).collect()
            }
            Family::TimeDelay => log(scales.delays.0, scales.delays.1, 8),
            Family::Adhesion => log(scales.adhesion_ranges.0, scales.adhesion_ranges.1, 9),
            Family::QuasiLinear => scales.time_constant_grid(),
            Family::SqueezeFilm => log(scales.squeeze_reaches.0, scales.squeeze_reaches.1, 9),
            _ => vec![0.0],
        }
    }

    pub(crate) fn has_shape(self) -> bool {
        matches!(
            self,
            Family::Relaxation
                | Family::Hysteresis
                | Family::StiffnessExponent
                | Family::TimeDelay
                | Family::Adhesion
                | Family::QuasiLinear
                | Family::SqueezeFilm
        )
    }
}

/// The excitation that separates two candidates.
pub(crate) fn would_separate(a: Family, b: Family) -> String {
    use Family::*;
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    match (a, b) {
        (SensorBias, SensorDrift) => "a longer recording with free space (a lift-off) at its end: a constant offset stays, a drift grows",
        (SensorDrift, OffsetDrift) | (SensorBias, OffsetDrift) => {
            "free space late in the recording (a lift-off): a sensor offset shows there, a moving surface zero does not; pushes to two depths also separate them unless the law is linear"
        }
        (Relaxation, Hysteresis) => {
            "a hold of several seconds (relaxation decays under held deformation, hysteresis does not act at rest) and pushes at two speeds"
        }
        (Relaxation, QuasiLinear) => {
            "holds at two depths: a quasi-linear branch relaxes in proportion to the law's elastic force, a Maxwell branch to the deformation"
        }
        (Hysteresis, Adhesion) | (Relaxation, Adhesion) => {
            "a retract well past the surface: an adhesion still pulls there, a loop of the surface's own force ends at it"
        }
        (Relaxation, _) | (_, Relaxation) => "a hold of several seconds after a fast push: only relaxation decays at rest",
        (Hysteresis, StiffnessExponent) => {
            "slow pushes to the same depths at two speeds: hysteresis differs between loading and unloading, the exponent does not"
        }
        (StiffnessExponent, OffsetDrift) => "repeated pushes to the same depth minutes apart: a moving zero shifts them, an exponent does not",
        (SensorBias, _) | (SensorDrift, _) => "free space before and after contact: a sensor offset shows without contact",
        (TimeDelay, _) | (_, TimeDelay) => {
            "a fast stop after a push, or pushes at two frequencies: a delay shifts the force after the motion has stopped, and its phase grows with frequency"
        }
        (Crosstalk, _) | (_, Crosstalk) => {
            "lateral motion at a held deformation: only crosstalk follows the tangential load"
        }
        (ToolGravity, _) | (_, ToolGravity) => "tilting the hand in free space: only the tool's weight follows the tilt",
        (MediumDrag, SqueezeFilm) => {
            "free space crossed at one speed from far away up to the surface: a squeeze film's drag grows as the gap closes, the medium's stays"
        }
        (MediumDrag, _) | (_, MediumDrag) | (SqueezeFilm, _) | (_, SqueezeFilm) => {
            "free space crossed at two speeds, both ways: only the medium's drag follows the hand's speed out of contact"
        }
        _ => "a hold of several seconds, pushes at two speeds and to two depths, and free space before and after",
    }
    .to_string()
}
