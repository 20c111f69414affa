//! What a plausible contact model can be ([`crate::ContactModel::plausible`]): the bounds the controller and
//! the simulator hold every model to.

/// The most effects a plausible model names ([`crate::ContactModel::plausible`]).
pub const MAX_EFFECTS: usize = 8;
/// The stiffest a plausible soft contact is [N/m]: the law's slope at [`PLAUSIBLE_DEPTH`] and every
/// relaxation branch together (the demo's sponge: 1.4e4; a rigid table: beyond 1e7). The simulated arm
/// at its 1 ms step is stable on it.
pub const MAX_CONTACT_STIFFNESS: f64 = 1e6;
/// The depth at which a plausible law's stiffness is taken \[m\].
pub const PLAUSIBLE_DEPTH: f64 = 0.1;
/// The exponents a, b, c of a plausible contact law (the papers' models use 1 to 2).
pub const PLAUSIBLE_EXPONENTS: std::ops::RangeInclusive<f64> = 0.0..=4.0;
/// The time constants of a plausible model's relaxation branches \[s\].
pub const TIME_CONSTANT_RANGE: std::ops::RangeInclusive<f64> = 1e-3..=1e3;
/// The largest hysteresis of a plausible model (a share of the elastic force).
pub const MAX_HYSTERESIS: f64 = 0.5;
/// The slowest speed over which a plausible model's hysteresis turns [m/s]: slower is a switch on the
/// sign of the sensor's noise.
pub const MIN_HYSTERESIS_SCALE: f64 = 1e-4;
/// The fastest surface offset drift of a plausible model [m/s]: a surface at rest.
pub const MAX_SURFACE_DRIFT: f64 = 1e-3;
/// The fastest sensor drift of a plausible model [N/s] (a warming F/T sensor drifts mN/s).
pub const MAX_SENSOR_DRIFT: f64 = 0.1;
/// The largest sensor bias of a plausible model \[N\].
pub const MAX_SENSOR_BIAS: f64 = 20.0;
/// The strongest pull-off of a plausible model's adhesion \[N\] (a suction cup on glass: tens of N).
pub const MAX_ADHESION: f64 = 50.0;
/// The farthest beyond the surface a plausible model's adhesion holds on \[m\].
pub const MAX_ADHESION_RANGE: f64 = 0.02;
/// The strongest viscous drag of a plausible model's medium [N·s/m]: a hand moving at 0.1 m/s through
/// water reads about a newton; this is ten times more. The controller subtracts the drag of the measured
/// rate from every reading, so a larger one would feed the rate's noise into the force it controls.
pub const MAX_MEDIUM_DRAG: f64 = 100.0;
/// The farthest from the surface a plausible model's squeeze film reaches \[m\] (half its damping at that
/// gap): a film as thick as a tool is wide.
pub const MAX_SQUEEZE_REACH: f64 = 0.02;
/// The fastest hand speed a [`crate::Effect::MediumDrag`]'s zero may have been read at [m/s].
pub const MAX_TARE_SPEED: f64 = 1.0;
