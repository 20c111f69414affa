//! The contact model: one serde type that the simulator, the estimator, the controller and the
//! discrepancy workflow all read and write.

use serde::{Deserialize, Serialize};

use crate::{ContactError, Tangential};

/// The named normal-force laws f = k zᵃ + λ zᵇ żᶜ (the force-control paper's eq. 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// Linear spring and damper: a = c = 1, b = 0.
    KelvinVoigt,
    /// Hertzian spring with deformation-scaled damping: a = b = 3/2, c = 1.
    HuntCrossley,
    /// Hertzian spring, damping scaled by √z: a = 3/2, b = 1/2, c = 1.
    AzadFeatherstone,
    /// The snake paper's sphere on a plane: f_n = k_n z^{3/2} (a = b = 3/2, c = 1; λ normally 0), with the Walton
    /// tangential law in [`Tangential`].
    HertzWalton,
    /// Any exponents, e.g. an estimated a.
    General,
}

impl Kind {
    /// The kinds an estimator compares (the force-control paper).
    pub const CANDIDATES: [Kind; 3] = [Kind::KelvinVoigt, Kind::HuntCrossley, Kind::AzadFeatherstone];

    /// Fixed exponents of a named kind; `None` for [`Kind::General`].
    pub fn exponents(self) -> Option<Exponents> {
        match self {
            Kind::KelvinVoigt => Some(Exponents { a: 1.0, b: 0.0, c: 1.0 }),
            Kind::HuntCrossley | Kind::HertzWalton => Some(Exponents { a: 1.5, b: 1.5, c: 1.0 }),
            Kind::AzadFeatherstone => Some(Exponents { a: 1.5, b: 0.5, c: 1.0 }),
            Kind::General => None,
        }
    }

    /// The name used in files and JSON (`kelvin_voigt`, …).
    pub fn id(self) -> &'static str {
        match self {
            Kind::KelvinVoigt => "kelvin_voigt",
            Kind::HuntCrossley => "hunt_crossley",
            Kind::AzadFeatherstone => "azad_featherstone",
            Kind::HertzWalton => "hertz_walton",
            Kind::General => "general",
        }
    }

    /// The name people use (`Kelvin-Voigt`, …).
    pub fn label(self) -> &'static str {
        match self {
            Kind::KelvinVoigt => "Kelvin-Voigt",
            Kind::HuntCrossley => "Hunt-Crossley",
            Kind::AzadFeatherstone => "Azad-Featherstone",
            Kind::HertzWalton => "Hertz-Walton",
            Kind::General => "general",
        }
    }
}

/// Exponents of f = k zᵃ + λ zᵇ żᶜ.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Exponents {
    pub a: f64,
    pub b: f64,
    pub c: f64,
}

/// A named augmentation of the base law (docs/discrepancy.md ids). Surface effects change the force the
/// surface exerts; sensor effects change what the F/T sensor reports of it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "id", rename_all = "snake_case", deny_unknown_fields)]
pub enum Effect {
    /// A Maxwell branch (spring k_m in series with a damper of time constant τ) in parallel with the base
    /// law: force relaxes under held deformation. Branch force s: ṡ = k_m ż − s/τ.
    ViscoelasticRelaxation { stiffness: f64, time_constant: f64 },
    /// Loading and unloading paths differ: the elastic force is scaled by 1 + h·tanh(ż / v₀).
    Hysteresis { fraction: f64, velocity_scale: f64 },
    /// The surface zero moves at a constant rate [m/s] along the contact normal (the snake paper's creep).
    ContactOffsetDrift { rate: f64 },
    /// Constant offset \[N\] of the measured normal force.
    SensorBias { offset: f64 },
    /// Offset of the measured normal force growing at a constant rate [N/s] since the sensor's last tare
    /// ([`EffectState::tare`]).
    SensorDrift { rate: f64 },
    /// The reading reaches the recording `delay` \[s\] after the force acts (a slow sensor chain or a skewed
    /// stamp): measured(t) = reading(t − delay), 0 ≤ delay ≤ [`MAX_DELAY`].
    TimeDelay { delay: f64 },
    /// Force channels mix (the snake paper: a sensor axis misaligned with the pushing axis): the normal reading
    /// gains coupling · F_t, F_t the tangential force the surface exerts on the hand, both in the frame of
    /// the normal. A misalignment by a small rotation ω of the sensing frame gives coupling ≈ n × ω.
    SensorCrosstalk { coupling: [f64; 3] },
    /// A tool mass the gravity compensation does not know \[kg\] (negative: it assumes too much): the normal
    /// reading gains mass · Δg_n, with Δg_n how gravity along the normal, as the sensor sees it, has changed
    /// since its last tare ([`SensorInputs::gravity_change`]); nothing while the hand keeps its orientation.
    ToolGravity { mass: f64 },
    /// The surface holds on to the hand on the way out (JKR/DMT-like adhesion): once pressed, it pulls
    /// with `force` · min(1, (z_peak − z)/(z_peak + range)) \[N\] as the deformation falls from the deepest
    /// z_peak of the present contact, the full pull-off `force` at `range` \[m\] beyond the surface, where it
    /// lets go; nothing while pressing deeper, nothing after letting go until the next contact.
    Adhesion { force: f64, range: f64 },
    /// Fung's quasi-linear viscoelasticity with one term, G(t) = 1 + g e^{−t/τ}: a branch driven by the
    /// elastic force k zᵃ instead of the deformation, ṡ = g · d(k zᵃ)/dt − s/τ. The fresh response is
    /// (1 + g) times the law's, relaxing to it with τ; for a linear law it is a Maxwell branch of g·k.
    QuasiLinearRelaxation { fraction: f64, time_constant: f64 },
    /// The medium the hand moves through (a liquid bath, a gel around the probe, an AFM cantilever in
    /// buffer) resists its motion along the normal, in contact and out of it: the reading gains
    /// `damping` · (ż − `tare_speed`) \[N\], ż [m/s] the rate of the deformation (> 0 towards the surface),
    /// `damping` [N·s/m] the medium's viscous drag, and `tare_speed` [m/s] the hand's speed while the
    /// sensor's zero was read (0 for a sensor tared at rest; an instrument that zeroes its force on the
    /// moving approach has zeroed the drag of that speed too).
    MediumDrag { damping: f64, tare_speed: f64 },
    /// The medium squeezed out between the hand and the surface as they close in (a tool pressing on
    /// tissue in saline, an AFM cantilever in buffer near its sample) resists the motion the more the
    /// thinner the film: the reading gains `damping` · `reach` / (gap + `reach`) · ż \[N\], gap = max(−z, 0)
    /// \[m\] the distance to the surface, so the whole `damping` [N·s/m] in contact, half of it at `reach`
    /// \[m\] from the surface, nothing far away. The drag of a sphere or a lever above a plane in a viscous
    /// liquid, b(h) = 6πη·a²/(h + h_eff) (Alcaraz et al., "Correction of microrheological measurements of
    /// soft samples with atomic force microscopy for the hydrodynamic drag on the cantilever"); beside a
    /// [`Effect::MediumDrag`], the same medium's drag far from the surface.
    SqueezeFilm { damping: f64, reach: f64 },
}

/// The longest [`Effect::TimeDelay`] a model may carry \[s\].
pub const MAX_DELAY: f64 = 1.0;

/// What the sensor effects read besides the normal force (see [`ContactModel::sense`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SensorInputs {
    /// Tangential force the surface exerts on the hand, in the frame of the normal \[N\].
    pub tangential_force: [f64; 3],
    /// ((R R_tareᵀ − I) g)·n [m/s²]: the change since the last tare of gravity along the normal as the
    /// sensor sees it (R the sensor's orientation now, R_tare at the tare, g gravity, n the normal; see
    /// [`gravity_change`]).
    pub gravity_change: f64,
}

/// [`SensorInputs::gravity_change`] from the sensor's rotation now and at its last tare (row-major 3×3,
/// sensor → frame of the normal), gravity g [m/s²] and the normal n in that frame.
pub fn gravity_change(now: &[[f64; 3]; 3], at_tare: &[[f64; 3]; 3], g: [f64; 3], n: [f64; 3]) -> f64 {
    // R_tareᵀ g: gravity in the sensor frame at the tare; R (·): back in the frame of the normal.
    let in_sensor: [f64; 3] = std::array::from_fn(|j| (0..3).map(|i| at_tare[i][j] * g[i]).sum());
    let seen: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| now[i][j] * in_sensor[j]).sum());
    (0..3).map(|i| (seen[i] - g[i]) * n[i]).sum()
}

impl Effect {
    pub fn id(&self) -> &'static str {
        match self {
            Effect::ViscoelasticRelaxation { .. } => "viscoelastic_relaxation",
            Effect::Hysteresis { .. } => "hysteresis",
            Effect::ContactOffsetDrift { .. } => "contact_offset_drift",
            Effect::SensorBias { .. } => "sensor_bias",
            Effect::SensorDrift { .. } => "sensor_drift",
            Effect::TimeDelay { .. } => "time_delay",
            Effect::SensorCrosstalk { .. } => "sensor_crosstalk",
            Effect::ToolGravity { .. } => "tool_gravity",
            Effect::Adhesion { .. } => "adhesion",
            Effect::QuasiLinearRelaxation { .. } => "quasi_linear_relaxation",
            Effect::MediumDrag { .. } => "medium_drag",
            Effect::SqueezeFilm { .. } => "squeeze_film",
        }
    }

    /// The parameters in the order of the file's fields (the form of a /contact_estimator/model message).
    pub fn parameter_list(&self) -> Vec<f64> {
        let n = match self {
            Effect::ViscoelasticRelaxation { .. }
            | Effect::Hysteresis { .. }
            | Effect::Adhesion { .. }
            | Effect::QuasiLinearRelaxation { .. }
            | Effect::MediumDrag { .. }
            | Effect::SqueezeFilm { .. } => 2,
            Effect::SensorCrosstalk { .. } => 3,
            _ => 1,
        };
        self.parameters()[..n].to_vec()
    }

    /// The effect `id` with the parameters of [`Self::parameter_list`], checked as a file's entry is.
    pub fn from_parameters(id: &str, p: &[f64]) -> Result<Effect, ContactError> {
        let arity = |n: usize| {
            if p.len() == n {
                Ok(())
            } else {
                Err(ContactError::InvalidModel(format!("effect `{id}` takes {n} parameters, not {}", p.len())))
            }
        };
        // (A stranger's id may be any length: only a known one is echoed whole.)
        let effect = match id {
            "viscoelastic_relaxation" => {
                arity(2).map(|_| Effect::ViscoelasticRelaxation { stiffness: p[0], time_constant: p[1] })
            }
            "hysteresis" => arity(2).map(|_| Effect::Hysteresis { fraction: p[0], velocity_scale: p[1] }),
            "contact_offset_drift" => arity(1).map(|_| Effect::ContactOffsetDrift { rate: p[0] }),
            "sensor_bias" => arity(1).map(|_| Effect::SensorBias { offset: p[0] }),
            "sensor_drift" => arity(1).map(|_| Effect::SensorDrift { rate: p[0] }),
            "time_delay" => arity(1).map(|_| Effect::TimeDelay { delay: p[0] }),
            "sensor_crosstalk" => arity(3).map(|_| Effect::SensorCrosstalk { coupling: [p[0], p[1], p[2]] }),
            "tool_gravity" => arity(1).map(|_| Effect::ToolGravity { mass: p[0] }),
            "adhesion" => arity(2).map(|_| Effect::Adhesion { force: p[0], range: p[1] }),
            "quasi_linear_relaxation" => {
                arity(2).map(|_| Effect::QuasiLinearRelaxation { fraction: p[0], time_constant: p[1] })
            }
            "medium_drag" => arity(2).map(|_| Effect::MediumDrag { damping: p[0], tare_speed: p[1] }),
            "squeeze_film" => arity(2).map(|_| Effect::SqueezeFilm { damping: p[0], reach: p[1] }),
            _ => {
                Err(ContactError::InvalidModel(format!("unknown effect `{}`", id.chars().take(40).collect::<String>())))
            }
        }?;
        effect.validate()?;
        Ok(effect)
    }

    fn parameters(&self) -> [f64; 3] {
        match *self {
            Effect::ViscoelasticRelaxation { stiffness, time_constant } => [stiffness, time_constant, 0.0],
            Effect::Hysteresis { fraction, velocity_scale } => [fraction, velocity_scale, 0.0],
            Effect::ContactOffsetDrift { rate } | Effect::SensorDrift { rate } => [rate, 0.0, 0.0],
            Effect::SensorBias { offset } => [offset, 0.0, 0.0],
            Effect::TimeDelay { delay } => [delay, 0.0, 0.0],
            Effect::SensorCrosstalk { coupling } => coupling,
            Effect::ToolGravity { mass } => [mass, 0.0, 0.0],
            Effect::Adhesion { force, range } => [force, range, 0.0],
            Effect::QuasiLinearRelaxation { fraction, time_constant } => [fraction, time_constant, 0.0],
            Effect::MediumDrag { damping, tare_speed } => [damping, tare_speed, 0.0],
            Effect::SqueezeFilm { damping, reach } => [damping, reach, 0.0],
        }
    }

    fn validate(&self) -> Result<(), ContactError> {
        let bad = |why: &str| Err(ContactError::InvalidModel(format!("effect `{}`: {why}", self.id())));
        if self.parameters().iter().any(|p| !p.is_finite()) {
            return bad("parameters must be finite");
        }
        match *self {
            Effect::ViscoelasticRelaxation { stiffness, time_constant } if stiffness < 0.0 || time_constant <= 0.0 => {
                bad("stiffness must be ≥ 0 and time_constant > 0")
            }
            Effect::Hysteresis { fraction, velocity_scale }
                if !(0.0..1.0).contains(&fraction) || velocity_scale <= 0.0 =>
            {
                bad("fraction must be in [0, 1) and velocity_scale > 0")
            }
            Effect::TimeDelay { delay } if !(0.0..=MAX_DELAY).contains(&delay) => {
                bad(&format!("delay must be in [0, {MAX_DELAY}] s"))
            }
            // A coupling of one would read the whole tangential load as normal force: not a small mixing.
            Effect::SensorCrosstalk { coupling } if coupling.iter().map(|c| c * c).sum::<f64>() >= 0.25 => {
                bad("|coupling| must be below 0.5")
            }
            Effect::ToolGravity { mass } if mass.abs() > 100.0 => bad("|mass| must be at most 100 kg"),
            Effect::Adhesion { force, range } if force < 0.0 || range <= 0.0 => bad("force must be ≥ 0 and range > 0"),
            Effect::QuasiLinearRelaxation { fraction, time_constant } if fraction < 0.0 || time_constant <= 0.0 => {
                bad("fraction must be ≥ 0 and time_constant > 0")
            }
            Effect::MediumDrag { damping, .. } if damping < 0.0 => bad(&format!("damping must be ≥ 0, not {damping}")),
            Effect::MediumDrag { tare_speed, .. } if tare_speed.abs() > MAX_TARE_SPEED => {
                bad(&format!("|tare_speed| must be at most {MAX_TARE_SPEED} m/s, not {tare_speed}"))
            }
            Effect::SqueezeFilm { damping, reach } if damping < 0.0 || reach <= 0.0 => {
                bad(&format!("damping must be ≥ 0 and reach > 0, not {damping} and {reach}"))
            }
            _ => Ok(()),
        }
    }
}

/// Everything known about a soft contact: the normal law, optionally the tangential law, and added
/// effects. `kind`, `stiffness`, `damping`, `exponents` read like the JSON of `softcontact identify`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ModelFile")]
pub struct ContactModel {
    pub kind: Kind,
    /// k.
    pub stiffness: f64,
    /// λ.
    pub damping: f64,
    pub exponents: Exponents,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tangential: Option<Tangential>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub effects: Vec<Effect>,
}

/// The file form: exponents may be left out for a named kind.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    kind: Kind,
    stiffness: f64,
    #[serde(default)]
    damping: f64,
    exponents: Option<Exponents>,
    tangential: Option<Tangential>,
    #[serde(default)]
    effects: Vec<Effect>,
}

impl TryFrom<ModelFile> for ContactModel {
    type Error = ContactError;
    fn try_from(f: ModelFile) -> Result<Self, ContactError> {
        let exponents = match (f.kind.exponents(), f.exponents) {
            (Some(named), Some(given)) if named != given => {
                return Err(ContactError::InvalidModel(format!(
                    "kind {} has exponents a={}, b={}, c={}; the file gives a={}, b={}, c={} (use kind general)",
                    f.kind.id(),
                    named.a,
                    named.b,
                    named.c,
                    given.a,
                    given.b,
                    given.c
                )));
            }
            (Some(named), _) => named,
            (None, Some(given)) => given,
            (None, None) => return Err(ContactError::InvalidModel("kind general needs exponents {a, b, c}".into())),
        };
        let model = ContactModel {
            kind: f.kind,
            stiffness: f.stiffness,
            damping: f.damping,
            exponents,
            tangential: f.tangential,
            effects: f.effects,
        };
        model.validate()?;
        Ok(model)
    }
}

/// sgn(x)·|x|ᶜ: the rate term keeps its sign when the surface is released.
#[inline]
fn signed_pow(x: f64, c: f64) -> f64 {
    if c == 1.0 { x } else { x.signum() * x.abs().powf(c) }
}

/// zᵉ, with the exponents of the named kinds computed without `powf`.
#[inline]
pub(crate) fn pow(z: f64, e: f64) -> f64 {
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

/// `v` if it is a finite number, else the error naming it.
pub fn finite(name: &'static str, v: f64) -> Result<f64, ContactError> {
    if v.is_finite() { Ok(v) } else { Err(ContactError::NonFinite { name, value: v }) }
}

pub use crate::effect_laws::*;
pub use crate::limits::*;

/// State of the effects that have memory (see [`ContactModel::step`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EffectState {
    /// Time since the model was applied \[s\].
    pub time: f64,
    /// Time since the sensor was last tared (or since the model was applied) \[s\]: a tare zeroes the
    /// offset the sensor has drifted, so [`Effect::SensorDrift`] counts from it.
    pub since_tare: f64,
    /// Force of each viscoelastic branch, in the order of `effects`.
    pub branch_force: Vec<f64>,
    /// The effective deformation of the previous step (None before the first): the branches are driven
    /// by how much the deformation changed over the step.
    pub last_deformation: Option<f64>,
    /// (time, reading) of the last [`Effect::TimeDelay`] span, oldest first: at most [`DELAY_LINE`].
    pub delay_line: std::collections::VecDeque<(f64, f64)>,
    /// The deepest effective deformation of the present contact while an [`Effect::Adhesion`] holds on
    /// (None before the first contact and after it let go).
    pub adhesion_peak: Option<f64>,
    /// The deformation's rate of the last step [m/s]: what an [`Effect::MediumDrag`] reads.
    pub rate: f64,
}

/// The distance to the surface after the state's last step \[m\]: of its effective deformation beyond the
/// surface, 0 in contact and before the first step.
#[inline]
pub fn gap_of(state: &EffectState) -> f64 {
    (-state.last_deformation.unwrap_or(0.0)).max(0.0)
}

/// The most readings a delay line keeps (one second at 10 kHz); with finer steps the delay is cut short.
pub const DELAY_LINE: usize = 10_000;

impl EffectState {
    /// The sensor was tared: the offset it has drifted since the last tare is zeroed.
    pub fn tare(&mut self) {
        self.since_tare = 0.0;
    }
}

impl ContactModel {
    /// A model of a named kind.
    pub fn new(kind: Kind, stiffness: f64, damping: f64) -> Result<Self, ContactError> {
        let exponents = kind.exponents().ok_or_else(|| {
            ContactError::InvalidModel("kind general needs exponents: use ContactModel::general".into())
        })?;
        let model = ContactModel { kind, stiffness, damping, exponents, tangential: None, effects: Vec::new() };
        model.validate()?;
        Ok(model)
    }

    /// A model with any exponents.
    pub fn general(stiffness: f64, damping: f64, exponents: Exponents) -> Result<Self, ContactError> {
        let model =
            ContactModel { kind: Kind::General, stiffness, damping, exponents, tangential: None, effects: Vec::new() };
        model.validate()?;
        Ok(model)
    }

    /// Checks what the force law needs: finite numbers, k > 0, λ ≥ 0, a > 0, b ≥ 0, c > 0.
    pub fn validate(&self) -> Result<(), ContactError> {
        let Exponents { a, b, c } = self.exponents;
        let numbers = [self.stiffness, self.damping, a, b, c];
        if numbers.iter().any(|v| !v.is_finite()) {
            return Err(ContactError::InvalidModel("stiffness, damping and exponents must be finite".into()));
        }
        if self.stiffness <= 0.0 || self.damping < 0.0 {
            return Err(ContactError::InvalidModel(format!(
                "stiffness must be > 0 and damping ≥ 0 (got k = {}, λ = {})",
                self.stiffness, self.damping
            )));
        }
        if a <= 0.0 || b < 0.0 || c <= 0.0 {
            return Err(ContactError::InvalidModel(format!("exponents need a > 0, b ≥ 0, c > 0 (got {a}, {b}, {c})")));
        }
        if let Some(t) = self.tangential {
            t.validate()?;
        }
        self.effects.iter().try_for_each(Effect::validate)
    }

    /// The medium's drag in contact \[N·s/m\], summed over its effects ([`Effect::drag_in_contact`]): what
    /// [`MAX_MEDIUM_DRAG`] bounds.
    pub fn medium_drag_in_contact(&self) -> f64 {
        self.effects.iter().map(Effect::drag_in_contact).sum()
    }

    /// Checks what a soft surface next to a robot can be, beyond [`ContactModel::validate`]'s physics: at
    /// most [`MAX_EFFECTS`] effects, relaxation time constants in [`TIME_CONSTANT_RANGE`], and — summed over
    /// repeated effects — a contact stiffness (the law's slope at [`PLAUSIBLE_DEPTH`] plus every relaxation
    /// branch) of at most [`MAX_CONTACT_STIFFNESS`], hysteresis of at most [`MAX_HYSTERESIS`], a surface
    /// drifting at most [`MAX_SURFACE_DRIFT`], a sensor drifting at most [`MAX_SENSOR_DRIFT`] and biased at
    /// most [`MAX_SENSOR_BIAS`], exponents in [`PLAUSIBLE_EXPONENTS`] and a tangential stiffness k_t·√z at
    /// [`PLAUSIBLE_DEPTH`] of at most [`MAX_CONTACT_STIFFNESS`]. The controller and the simulator refuse a
    /// model beyond them: such numbers are a mistake, not a surface.
    pub fn plausible(&self) -> Result<(), ContactError> {
        self.validate()?;
        let bad = |why: String| Err(ContactError::InvalidModel(format!("implausible: {why}")));
        if self.effects.len() > MAX_EFFECTS {
            return bad(format!("{} effects, more than {MAX_EFFECTS}", self.effects.len()));
        }
        let Exponents { a, b, c } = self.exponents;
        if ![a, b, c].iter().all(|x| PLAUSIBLE_EXPONENTS.contains(x)) {
            return bad(format!("exponents {a}, {b}, {c} outside {PLAUSIBLE_EXPONENTS:?}"));
        }
        let tangential = self.tangential.map_or(0.0, |t| t.stiffness * PLAUSIBLE_DEPTH.sqrt());
        if tangential > MAX_CONTACT_STIFFNESS {
            return bad(format!("a tangential stiffness of {tangential:.3e} N/m at {PLAUSIBLE_DEPTH} m"));
        }
        let mut stiffness = self.stiffness * a * pow(PLAUSIBLE_DEPTH, a - 1.0);
        let (mut hysteresis, mut surface_drift, mut sensor_drift, mut bias) = (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
        let mut adhesion = 0.0_f64;
        for e in &self.effects {
            match *e {
                Effect::ViscoelasticRelaxation { time_constant, .. }
                    if !TIME_CONSTANT_RANGE.contains(&time_constant) =>
                {
                    return bad(format!(
                        "a relaxation time constant of {time_constant} s, outside {TIME_CONSTANT_RANGE:?} s"
                    ));
                }
                Effect::ViscoelasticRelaxation { stiffness: k, .. } => stiffness += k,
                Effect::QuasiLinearRelaxation { time_constant, .. }
                    if !TIME_CONSTANT_RANGE.contains(&time_constant) =>
                {
                    return bad(format!(
                        "a quasi-linear time constant of {time_constant} s, outside {TIME_CONSTANT_RANGE:?} s"
                    ));
                }
                // The fresh response adds g times the law's slope.
                Effect::QuasiLinearRelaxation { fraction, .. } => {
                    stiffness += fraction * self.stiffness * a * pow(PLAUSIBLE_DEPTH, a - 1.0)
                }
                Effect::Hysteresis { velocity_scale, .. } if velocity_scale < MIN_HYSTERESIS_SCALE => {
                    return bad(format!(
                        "hysteresis turning over {velocity_scale} m/s, slower than {MIN_HYSTERESIS_SCALE} m/s"
                    ));
                }
                Effect::Hysteresis { fraction, .. } => hysteresis += fraction,
                Effect::ContactOffsetDrift { rate } => surface_drift += rate,
                Effect::SensorDrift { rate } => sensor_drift += rate,
                Effect::SensorBias { offset } => bias += offset,
                Effect::Adhesion { range, .. } if range > MAX_ADHESION_RANGE => {
                    return bad(format!(
                        "adhesion holding on {range} m beyond the surface, farther than {MAX_ADHESION_RANGE} m"
                    ));
                }
                Effect::Adhesion { force, .. } => adhesion += force,
                Effect::SqueezeFilm { reach, .. } if reach > MAX_SQUEEZE_REACH => {
                    return bad(format!(
                        "a squeeze film reaching {reach} m from the surface, farther than {MAX_SQUEEZE_REACH} m"
                    ));
                }
                _ => {}
            }
        }
        if adhesion > MAX_ADHESION {
            return bad(format!("an adhesion pulling {adhesion:.4e} N in all, more than {MAX_ADHESION} N"));
        }
        let drag = self.medium_drag_in_contact();
        if drag > MAX_MEDIUM_DRAG {
            return bad(format!("a medium dragging {drag:.4e} N·s/m in all, more than {MAX_MEDIUM_DRAG} N·s/m"));
        }
        if stiffness.is_nan() || stiffness > MAX_CONTACT_STIFFNESS {
            return bad(format!(
                "a contact stiffness of {stiffness:.3e} N/m at {PLAUSIBLE_DEPTH} m (law and branches), more than {MAX_CONTACT_STIFFNESS:.0e} N/m"
            ));
        }
        if hysteresis > MAX_HYSTERESIS {
            return bad(format!("hysteresis of {hysteresis} in all, more than {MAX_HYSTERESIS}"));
        }
        if surface_drift.abs() > MAX_SURFACE_DRIFT {
            return bad(format!("the surface drifting {surface_drift} m/s, faster than {MAX_SURFACE_DRIFT} m/s"));
        }
        if sensor_drift.abs() > MAX_SENSOR_DRIFT {
            return bad(format!("the sensor drifting {sensor_drift} N/s, faster than {MAX_SENSOR_DRIFT} N/s"));
        }
        if bias.abs() > MAX_SENSOR_BIAS {
            return bad(format!("a sensor bias of {bias} N, more than {MAX_SENSOR_BIAS} N (a tare zeroes it)"));
        }
        Ok(())
    }

    pub fn from_yaml(text: &str) -> Result<Self, ContactError> {
        serde_yaml_ng::from_str(text).map_err(|e| {
            // A model that parses but fails its check already says "invalid contact model".
            let said = e.to_string();
            ContactError::InvalidModel(
                said.strip_prefix("invalid contact model: ").map_or(said.clone(), str::to_string),
            )
        })
    }

    pub fn to_yaml(&self) -> String {
        serde_yaml_ng::to_string(self).expect("a contact model always serialises")
    }

    /// The elastic part k zᵃ and the rate part λ zᵇ żᶜ, for z > 0.
    #[inline]
    fn parts(&self, z: f64, zdot: f64) -> (f64, f64) {
        let e = &self.exponents;
        (self.stiffness * pow(z, e.a), self.damping * pow(z, e.b) * signed_pow(zdot, e.c))
    }

    /// Normal force of the base law at deformation z \[m\] and rate ż [m/s]: k zᵃ + λ zᵇ żᶜ for z > 0,
    /// 0 out of contact, and never negative (a soft surface pushes, it does not pull).
    pub fn force(&self, z: f64, zdot: f64) -> Result<f64, ContactError> {
        let (z, zdot) = (finite("z", z)?, finite("ż", zdot)?);
        if z <= 0.0 {
            return Ok(0.0);
        }
        let (elastic, rate) = self.parts(z, zdot);
        Ok((elastic + rate).max(0.0))
    }

    /// ∂f/∂z and ∂f/∂ż of [`ContactModel::force`] (zero where the force is zero).
    pub fn derivatives(&self, z: f64, zdot: f64) -> Result<(f64, f64), ContactError> {
        let (z, zdot) = (finite("z", z)?, finite("ż", zdot)?);
        if z <= 0.0 || self.force(z, zdot)? == 0.0 {
            return Ok((0.0, 0.0));
        }
        let Exponents { a, b, c } = self.exponents;
        let rate = signed_pow(zdot, c);
        let df_dz = self.stiffness * a * pow(z, a - 1.0) + self.damping * b * pow(z, b - 1.0) * rate;
        let df_dzdot = if zdot == 0.0 && c < 1.0 {
            f64::INFINITY
        } else {
            self.damping * pow(z, b) * c * zdot.abs().powf(c - 1.0)
        };
        Ok((df_dz, df_dzdot))
    }

    /// The deformation that holds force f at rest (ż = 0): z = (f/k)^{1/a} (the force-control paper's eq. 19).
    pub fn deformation_for_force(&self, f: f64) -> Result<f64, ContactError> {
        let f = finite("force", f)?;
        if f < 0.0 {
            return Err(ContactError::NegativeForce(f));
        }
        Ok((f / self.stiffness).powf(1.0 / self.exponents.a))
    }

    /// A fresh state for [`ContactModel::step`].
    pub fn effect_state(&self) -> EffectState {
        EffectState { branch_force: vec![0.0; self.effects.len()], ..EffectState::default() }
    }

    /// Advances the effects with memory by dt and returns (surface force, measured force): the force
    /// the surface exerts with its surface effects, and what a sensor with the sensor effects reads
    /// without tangential load or a change of orientation ([`ContactModel::sense`] with default inputs).
    pub fn step(&self, state: &mut EffectState, z: f64, zdot: f64, dt: f64) -> Result<(f64, f64), ContactError> {
        let surface = self.step_surface(state, z, zdot, dt)?;
        Ok((surface, self.sense(state, surface, &SensorInputs::default())?))
    }

    /// Advances time and the surface effects by dt and returns the force the surface exerts (≥ 0 but for
    /// an adhesion's pull). Call
    /// [`ContactModel::sense`] after it, once per step, for what the sensor reads.
    pub fn step_surface(&self, state: &mut EffectState, z: f64, zdot: f64, dt: f64) -> Result<f64, ContactError> {
        let (z, zdot, dt) = (finite("z", z)?, finite("ż", zdot)?, finite("dt", dt)?);
        state.time += dt;
        state.since_tare += dt;
        state.rate = zdot;
        let (z_eff, scale) = self.effective(state.time, z, zdot);
        let mut surface = 0.0;
        if z_eff > 0.0 {
            let (elastic, rate) = self.parts(z_eff, zdot);
            surface = elastic * scale + rate;
        }
        // The part of the step's deformation change made in contact (the branches start from rest at the
        // surface); the rate held over the step before the first one.
        let last = state.last_deformation.unwrap_or(z_eff - zdot * dt).max(0.0);
        let change = z_eff - last;
        // The same for the law's elastic force (the quasi-linear branches).
        let a = self.exponents.a;
        let elastic_change = self.stiffness * (pow(z_eff.max(0.0), a) - pow(last, a));
        state.last_deformation = Some(z_eff);
        for (i, e) in self.effects.iter().enumerate() {
            let (drive, time_constant) = match *e {
                Effect::ViscoelasticRelaxation { stiffness, time_constant } => (stiffness * change, time_constant),
                Effect::QuasiLinearRelaxation { fraction, time_constant } => (fraction * elastic_change, time_constant),
                _ => continue,
            };
            let s = &mut state.branch_force[i];
            *s = if z_eff > 0.0 { maxwell_step(*s, drive, dt, time_constant) } else { 0.0 };
            surface += *s;
        }
        state.adhesion_peak = self.adhesion_peak(state.adhesion_peak, z_eff);
        let (pull, _) = self.adhesion_pull(state.adhesion_peak, z_eff);
        Ok(surface.max(0.0) - pull)
    }

    /// The deepest deformation of the present contact after a step to z_eff: deeper in contact, kept
    /// beyond the surface while an adhesion holds on, forgotten once every one has let go.
    #[inline]
    fn adhesion_peak(&self, peak: Option<f64>, z_eff: f64) -> Option<f64> {
        let reach = self
            .effects
            .iter()
            .filter_map(|e| if let Effect::Adhesion { range, .. } = *e { Some(range) } else { None })
            .fold(None, |r: Option<f64>, x| Some(r.map_or(x, |r| r.max(x))))?;
        next_adhesion_peak(peak, z_eff, reach)
    }

    /// The adhesions' pull [N] at z_eff with the contact's deepest deformation `peak`, and its derivative
    /// along z (≤ 0: the pull eases as the hand presses back in).
    #[inline]
    fn adhesion_pull(&self, peak: Option<f64>, z_eff: f64) -> (f64, f64) {
        let Some(peak) = peak else { return (0.0, 0.0) };
        let (mut pull, mut slope) = (0.0, 0.0);
        for e in &self.effects {
            if let Effect::Adhesion { force, range } = *e
                && z_eff >= -range
            {
                let share = adhesion_share(peak, z_eff, range);
                pull += force * share;
                if share > 0.0 && share < 1.0 {
                    slope -= force / (peak + range);
                }
            }
        }
        (pull, slope)
    }

    /// The deformation the law sees at `time` (the surface moved by its offset drift) and the factor of
    /// the elastic force (hysteresis by the direction of motion).
    #[inline]
    fn effective(&self, time: f64, z: f64, zdot: f64) -> (f64, f64) {
        let mut z_eff = z;
        let mut scale = 1.0;
        for e in &self.effects {
            match *e {
                Effect::ContactOffsetDrift { rate } => z_eff -= rate * time,
                Effect::Hysteresis { fraction, velocity_scale } => {
                    scale *= 1.0 + fraction * (zdot / velocity_scale).tanh()
                }
                _ => {}
            }
        }
        (z_eff, scale)
    }

    /// The surface force and its derivative along z [N/m] after the deformation went from the state's
    /// last one to z over the next dt seconds and stopped there: [`ContactModel::step_surface`] with ż = 0
    /// (dt = 0: at once, every relaxation branch takes the change through its spring), without changing
    /// the state. Allocates nothing: the hold of an augmented model solves it every control tick.
    pub fn force_at_rest(&self, state: &EffectState, z: f64, dt: f64) -> Result<(f64, f64), ContactError> {
        let (z, dt) = (finite("z", z)?, finite("dt", dt)?);
        let (z_eff, _) = self.effective(state.time + dt, z, 0.0);
        let (pull, pull_slope) = self.adhesion_pull(self.adhesion_peak(state.adhesion_peak, z_eff), z_eff);
        if z_eff <= 0.0 {
            return Ok((-pull, -pull_slope));
        }
        let a = self.exponents.a;
        let (mut force, mut slope) = (self.stiffness * pow(z_eff, a), self.stiffness * a * pow(z_eff, a - 1.0));
        let last = state.last_deformation.unwrap_or(z_eff).max(0.0);
        let change = z_eff - last;
        let elastic_change = self.stiffness * (pow(z_eff, a) - pow(last, a));
        let elastic_slope = self.stiffness * a * pow(z_eff, a - 1.0);
        for (i, e) in self.effects.iter().enumerate() {
            let (drive, drive_slope, time_constant) = match *e {
                Effect::ViscoelasticRelaxation { stiffness, time_constant } => {
                    (stiffness * change, stiffness, time_constant)
                }
                Effect::QuasiLinearRelaxation { fraction, time_constant } => {
                    (fraction * elastic_change, fraction * elastic_slope, time_constant)
                }
                _ => continue,
            };
            let s = state.branch_force.get(i).copied().unwrap_or(0.0);
            force += maxwell_step(s, drive, dt, time_constant);
            slope += maxwell_step(0.0, drive_slope, dt, time_constant);
        }
        Ok((force.max(0.0) - pull, slope - pull_slope))
    }

    /// What the named sensor effects add to a reading now \[N\]: the bias, the drift since the last
    /// tare and the medium's drag at the last step's rate. A reading minus it is the surface force (the
    /// effects that need the tangential force, the orientation or the past are not in it).
    pub fn sensor_offset(&self, state: &EffectState) -> f64 {
        self.effects
            .iter()
            .map(|e| match *e {
                Effect::SensorBias { offset } => offset,
                Effect::SensorDrift { rate } => rate * state.since_tare,
                Effect::MediumDrag { .. } | Effect::SqueezeFilm { .. } => e.drag(state.rate, gap_of(state)),
                _ => 0.0,
            })
            .sum()
    }

    /// What the sensor reads along the normal of the surface force of this step (after
    /// [`ContactModel::step_surface`]): plus bias, drift, crosstalk, unknown tool weight and the medium's
    /// drag at the step's rate, the whole
    /// reading delayed by a time delay (linear interpolation between steps; before the first step the
    /// first reading).
    pub fn sense(&self, state: &mut EffectState, surface: f64, inputs: &SensorInputs) -> Result<f64, ContactError> {
        let surface = finite("surface force", surface)?;
        let gravity = finite("gravity change", inputs.gravity_change)?;
        for (i, &f) in inputs.tangential_force.iter().enumerate() {
            finite(["F_t x", "F_t y", "F_t z"][i], f)?;
        }
        let mut reading = surface;
        let mut delay = None;
        for e in &self.effects {
            match *e {
                Effect::SensorBias { offset } => reading += offset,
                Effect::SensorDrift { rate } => reading += rate * state.since_tare,
                Effect::SensorCrosstalk { coupling } => {
                    reading += (0..3).map(|i| coupling[i] * inputs.tangential_force[i]).sum::<f64>()
                }
                Effect::ToolGravity { mass } => reading += mass * gravity,
                Effect::MediumDrag { .. } | Effect::SqueezeFilm { .. } => reading += e.drag(state.rate, gap_of(state)),
                Effect::TimeDelay { delay: d } => delay = Some(d),
                _ => {}
            }
        }
        let Some(delay) = delay else { return Ok(reading) };
        let line = &mut state.delay_line;
        line.push_back((state.time, reading));
        let target = state.time - delay;
        while line.len() > DELAY_LINE || (line.len() > 1 && line[1].0 <= target) {
            line.pop_front();
        }
        let (t0, r0) = line[0];
        Ok(match line.get(1) {
            Some(&(t1, r1)) if target > t0 => r0 + (r1 - r0) * (target - t0) / (t1 - t0),
            _ => r0,
        })
    }
}
