//! The scales of one record that the shape grids and floors follow, and where a shape is a bound.

use super::*;

/// Relaxation branches (time constants) the workflow names at most.
pub const MAX_RELAXATION_BRANCHES: usize = 2;

/// The time constants a relaxation branch may have, in samples (from two sample periods: over one, a
/// branch is a step, not a decay)...
pub const RELAXATION_MIN_SAMPLES: f64 = 2.0;
/// ...and as a share of the record's duration (a slower branch is a drift within the record).
pub const RELAXATION_MAX_SHARE: f64 = 0.5;
/// The grid of time constants is anchored at this many samples, with the same spacing below it down to
/// [`RELAXATION_MIN_SAMPLES`] (see [`Scales::time_constant_grid`]).
pub const TIME_CONSTANT_GRID_FROM: f64 = 5.0;

/// The least range of the gravity change along the normal [m/s²] under which `tool_gravity` is not
/// tried: about a 6° tilt from the tare's orientation.
pub const MIN_GRAVITY_CHANGE: f64 = 0.05;

/// The delays screened, in sample periods: from half a period (shorter lags belong to the nominal chain:
/// the sensor's filter, the stamp skew between wrench and pose, the pairing with the newest pose) to 25.
pub const DELAY_SAMPLES: (f64, f64) = (0.5, 25.0);

/// The exponents a′ screened.
pub(crate) const EXPONENT_RANGE: (f64, f64) = (0.8, 2.5);

/// A shape within this factor of its range's end is a bound, not a finding: it is not named.
pub(crate) const EDGE: f64 = 1.05;

/// The scales of one record that the shape grids and the velocity floor follow: nothing assumes a
/// robot-sized contact (1 nN to 10 kN, 1 nm to 10 cm, any sample period).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Scales {
    /// The record's median sample period \[s\].
    pub sample_period: f64,
    /// The 95th percentile of |ż| [m/s].
    pub p95_speed: f64,
    /// The speed a quarter of the moving in-contact samples exceed [m/s].
    pub saturating_speed: f64,
    /// The relaxation time constants screened \[s\].
    pub time_constants: (f64, f64),
    /// The delays screened \[s\].
    pub delays: (f64, f64),
    /// The adhesion ranges screened \[m\]: from a fiftieth of the deepest deformation to twice it.
    pub adhesion_ranges: (f64, f64),
    /// The reaches of a squeeze film screened \[m\]: from a fiftieth of the deepest deformation to half the
    /// farthest distance from the surface the record goes (at most [`softcontact_contact::MAX_SQUEEZE_REACH`]).
    pub squeeze_reaches: (f64, f64),
}

impl Scales {
    pub fn of(series: &Series, v_th: f64) -> Self {
        let mut dt = step_sizes(series);
        dt.sort_by(f64::total_cmp);
        let sample_period = dt.get(dt.len() / 2).copied().unwrap_or(0.0).max(f64::MIN_POSITIVE);
        let duration = series.t.last().copied().unwrap_or(0.0) - series.t.first().copied().unwrap_or(0.0);
        let lo = RELAXATION_MIN_SAMPLES * sample_period;
        let deepest = series.z.iter().cloned().fold(0.0, f64::max).max(f64::MIN_POSITIVE);
        Scales {
            sample_period,
            p95_speed: p95_speed(series).max(f64::MIN_POSITIVE),
            saturating_speed: saturating_speed(series, v_th),
            time_constants: (lo, (RELAXATION_MAX_SHARE * duration).max(4.0 * TIME_CONSTANT_GRID_FROM * sample_period)),
            delays: (DELAY_SAMPLES.0 * sample_period, (DELAY_SAMPLES.1 * sample_period).min(MAX_DELAY)),
            adhesion_ranges: (0.02 * deepest, 2.0 * deepest),
            squeeze_reaches: {
                let farthest = series.z.iter().map(|z| -z).fold(0.0, f64::max);
                (0.02 * deepest, (0.5 * farthest).min(softcontact_contact::MAX_SQUEEZE_REACH).max(0.1 * deepest))
            },
        }
    }

    /// The relaxation time constants screened: 14 on a log scale from [`TIME_CONSTANT_GRID_FROM`] samples
    /// to the range's top, and below them at the same spacing down to the range's bottom.
    pub fn time_constant_grid(&self) -> Vec<f64> {
        let (lo, hi) = self.time_constants;
        let from = (TIME_CONSTANT_GRID_FROM * self.sample_period).clamp(lo, hi / 4.0);
        let ratio = (hi / from).powf(1.0 / 13.0);
        let below = (1..).map(|k| from / ratio.powi(k)).take_while(|&tau| tau >= lo * 0.999);
        let mut grid: Vec<f64> = below.collect::<Vec<_>>().into_iter().rev().collect();
        grid.extend((0..14).map(|i| from * ratio.powi(i)));
        grid
    }

    /// A shape at an end of the range it was screened on: a bound, not a finding (see [`Bound`]).
    pub(crate) fn at_edge(&self, family: Family, shape: f64) -> Option<(f64, f64)> {
        let range = match family {
            Family::Relaxation | Family::QuasiLinear => self.time_constants,
            Family::Hysteresis => (0.01 * self.p95_speed, self.saturating_speed),
            Family::TimeDelay => self.delays,
            Family::Adhesion => self.adhesion_ranges,
            Family::SqueezeFilm => self.squeeze_reaches,
            Family::StiffnessExponent => {
                let inside = shape > EXPONENT_RANGE.0 + 0.02 && shape < EXPONENT_RANGE.1 - 0.02;
                return (!inside).then_some(EXPONENT_RANGE);
            }
            _ => return None,
        };
        (!Scales::inside(shape, range)).then_some(range)
    }

    /// Inside a range, not at its ends (a log scale).
    pub(crate) fn inside(x: f64, (lo, hi): (f64, f64)) -> bool {
        x > lo * EDGE && x < hi / EDGE
    }
}

/// Hysteresis is named only when a quarter of the moving in-contact samples are faster than its velocity
/// scale v₀ (so that the recording's loops saturate): v₀ at most this percentile of their speed.
pub const HYSTERESIS_SATURATION_PERCENTILE: f64 = 0.75;
