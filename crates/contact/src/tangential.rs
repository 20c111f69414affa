//! The tangential contact law: the one description of the force a soft contact resists sideways motion
//! with, for the simulator, the discrepancy workflow and the offline tools.
//!
//! Sphere of radius R pressed δ_n deep (contact radius a = √(R δ_n)) and displaced δ_t sideways, normal
//! force P, tangential force T, friction coefficient μ. Two laws, chosen per model file (`law`):
//!
//! - **Walton** (the snake paper, eqs. 3–4):
//!   T = k_t √δ_n δ_t, a function of the present displacement only, limited to |T| ≤ μP.
//! - **Mindlin–Deresiewicz** (R. D. Mindlin and H. Deresiewicz, "Elastic spheres in contact under varying
//!   oblique forces", 1953): T is state, advanced by increments. Without slip dT = 8G*a dδ_t; since
//!   Walton's k_t = (16/3) G* √R, that is dT = (3/2) k_t √δ_n dδ_t with the same k_t, so both laws agree
//!   exactly on every straight path from the origin and differ off them — the path dependence the snake paper
//!   measured and could not model. An increment slips nowhere while the normal force grows at least as
//!   fast as the tangential one (dP > 0 and |dT| ≤ μ dP); otherwise an annulus slips (microslip) and the
//!   tangent stiffness falls, by the factor θ of the loading case (Thornton's form of the
//!   Mindlin–Deresiewicz rules, "Interparticle sliding in the presence of adhesion", as geoLAMMPS'
//!   `pair_gran_HMD_history` implements it):
//!   - loading:   θ³ = 1 − (s T + μ dP) / (μP),             dT = θ K dδ + s μ (1 − θ) dP
//!   - unloading: θ³ = 1 − (s (T* − T) + 2μ dP) / (2μP),    dT = θ K dδ − s μ (1 − θ) dP
//!   - reloading: θ³ = 1 − (s (T − T**) + 2μ dP) / (2μP),   dT = θ K dδ + s μ (1 − θ) dP
//!
//!   with K = 8G*a, s the sign of the first loading, T* the force where loading turned to unloading and
//!   T** where unloading turned to reloading (both shift by ±μ dP as the normal force changes). At constant
//!   P this is Cattaneo–Mindlin, T = μP[1 − (1 − k_t √δ_n δ_t/(μP))^{3/2}], and unloading follows the
//!   loading curve doubled about the turning point (Masing). |T| ≤ μP always; at the cap the contact slides.
//!   The memory is one loop deep: a reversal while reloading starts a new unloading. The law acts along one
//!   axis, the direction of the first tangential motion (the snake paper's paths lie in one plane); motion across
//!   it is carried by the Walton law and the whole force is capped at μP.
//!
//! The no-slip increment uses the mean contact radius over the step (exact on any straight step in the
//! (δ_n, δ_t) plane), the microslip increment a Heun step of the θ rule.

use serde::{Deserialize, Serialize};

use crate::model::finite;
use crate::{ContactError, ContactModel};

/// The tangential law of a model: its stiffness, friction, and whether it carries history.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tangential {
    /// Walton's k_t [N/m^{3/2}] (f_t = k_t √z δ_t on straight paths, either law).
    pub stiffness: f64,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// `walton` (default) or `mindlin_deresiewicz`.
    #[serde(default, skip_serializing_if = "TangentialLaw::is_walton")]
    pub law: TangentialLaw,
}

/// Which tangential law a model uses (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TangentialLaw {
    /// T = k_t √δ_n δ_t: path-independent.
    #[default]
    Walton,
    /// Incremental, with microslip and turning points: path-dependent.
    MindlinDeresiewicz,
}

impl TangentialLaw {
    fn is_walton(&self) -> bool {
        *self == TangentialLaw::Walton
    }

    pub fn id(self) -> &'static str {
        match self {
            TangentialLaw::Walton => "walton",
            TangentialLaw::MindlinDeresiewicz => "mindlin_deresiewicz",
        }
    }
}

impl Tangential {
    /// Walton's law, the default.
    pub fn walton(stiffness: f64, friction: f64) -> Self {
        Tangential { stiffness, friction, law: TangentialLaw::Walton }
    }

    /// The incremental Mindlin–Deresiewicz law with the same k_t and μ.
    pub fn mindlin_deresiewicz(stiffness: f64, friction: f64) -> Self {
        Tangential { stiffness, friction, law: TangentialLaw::MindlinDeresiewicz }
    }

    pub(crate) fn validate(&self) -> Result<(), ContactError> {
        if self.stiffness.is_finite() && self.stiffness >= 0.0 && self.friction.is_finite() && self.friction >= 0.0 {
            Ok(())
        } else {
            Err(ContactError::InvalidModel("tangential stiffness and friction must be finite and ≥ 0".into()))
        }
    }
}

/// Where an unloading or reloading stands in the Mindlin–Deresiewicz rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
enum Phase {
    #[default]
    Loading,
    Unloading,
    Reloading,
}

/// The memory of the Mindlin–Deresiewicz law along one axis: the force and its turning points. Starts
/// (and restarts, out of contact) at zero displacement, zero force.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MindlinDeresiewicz {
    /// T [N], signed along the axis.
    force: f64,
    /// s: the sign of the first loading (0 before any tangential motion).
    sign: f64,
    phase: Phase,
    /// T*: where loading (or reloading) turned to unloading.
    turning: f64,
    /// T**: where unloading turned to reloading.
    reversal: f64,
    last_z: f64,
    last_delta: f64,
    last_normal: f64,
}

impl MindlinDeresiewicz {
    /// The tangential force T \[N\] now.
    pub fn force(&self) -> f64 {
        self.force
    }

    /// Advances the law to normal deformation `z`, tangential displacement `delta` (signed, from where
    /// contact began, along the axis) and normal force `normal_force`, with stiffness k_t and friction μ of
    /// `law` (its `law` field is not read: this is the incremental law). Returns T and whether the contact
    /// slides (|T| = μP). Out of contact (z ≤ 0 or P ≤ 0) the memory clears and T = 0.
    pub fn step(
        &mut self,
        law: &Tangential,
        z: f64,
        delta: f64,
        normal_force: f64,
    ) -> Result<(f64, bool), ContactError> {
        let (z, delta, p) = (finite("z", z)?, finite("δ_t", delta)?, finite("normal force", normal_force)?);
        let mu = law.friction;
        if z <= 0.0 || p <= 0.0 || mu * p <= 0.0 {
            *self = MindlinDeresiewicz::default();
            return Ok((0.0, false));
        }
        let (dd, dp) = (delta - self.last_delta, p - self.last_normal);
        // 8G*ā over the step, ā the mean contact radius: (3/2) k_t · mean √z (exact on a straight step).
        let stiffness = 1.5 * law.stiffness * mean_sqrt(self.last_z, z);
        self.turn(dd);
        let elastic = stiffness * dd;
        if dp > 0.0 && elastic.abs() <= mu * dp {
            // The normal force grows at least as fast as μ times the tangential one: nothing slips.
            self.force += elastic;
        } else if dd != 0.0 || dp != 0.0 {
            // Microslip: Heun's step of the θ rule.
            let first = self.microslip(self.force, stiffness, dd, dp, p, mu);
            let second = self.microslip(self.force + first, stiffness, dd, dp, p, mu);
            self.force += 0.5 * (first + second);
        }
        // The turning points follow the normal force (their loading curves move with it).
        let shift = self.sign * mu * dp;
        match self.phase {
            Phase::Loading => {}
            Phase::Unloading => self.turning += shift,
            Phase::Reloading => {
                self.turning += shift;
                self.reversal -= shift;
            }
        }
        self.settle();
        let limit = mu * p;
        let slides = self.force.abs() > limit;
        if slides {
            self.force = limit.copysign(self.force);
        }
        (self.last_z, self.last_delta, self.last_normal) = (z, delta, p);
        Ok((self.force, slides))
    }

    /// Records a reversal of the tangential motion: a turning point and the next phase.
    fn turn(&mut self, dd: f64) {
        if dd == 0.0 {
            return;
        }
        if self.sign == 0.0 {
            self.sign = dd.signum();
        }
        let forward = dd * self.sign > 0.0;
        match (self.phase, forward) {
            (Phase::Loading | Phase::Reloading, false) => {
                (self.phase, self.turning, self.reversal) = (Phase::Unloading, self.force, 0.0);
            }
            (Phase::Unloading, true) => (self.phase, self.reversal) = (Phase::Reloading, self.force),
            _ => {}
        }
    }

    /// A loop that closed goes back to the loading curve it left: reloading past T* continues the loading;
    /// unloading past −T* reaches the loading curve of the other direction.
    fn settle(&mut self) {
        let s = self.sign;
        match self.phase {
            Phase::Reloading if s * self.force >= s * self.turning => {
                (self.phase, self.turning, self.reversal) = (Phase::Loading, 0.0, 0.0);
            }
            Phase::Unloading if s * self.force <= -s * self.turning => {
                (self.sign, self.phase, self.turning, self.reversal) = (-s, Phase::Loading, 0.0, 0.0);
            }
            _ => {}
        }
    }

    /// dT of the θ rule for the present phase, from force `t`.
    fn microslip(&self, t: f64, stiffness: f64, dd: f64, dp: f64, p: f64, mu: f64) -> f64 {
        let s = self.sign;
        let (used, along) = match self.phase {
            Phase::Loading => ((s * t + mu * dp) / (mu * p), s),
            Phase::Unloading => ((s * (self.turning - t) + 2.0 * mu * dp) / (2.0 * mu * p), -s),
            Phase::Reloading => ((s * (t - self.reversal) + 2.0 * mu * dp) / (2.0 * mu * p), s),
        };
        let theta = (1.0 - used).clamp(0.0, 1.0).cbrt();
        theta * stiffness * dd + along * mu * (1.0 - theta) * dp
    }
}

/// The mean of √z over [z0, z1] (both ≥ 0).
fn mean_sqrt(z0: f64, z1: f64) -> f64 {
    let z0 = z0.max(0.0);
    if (z1 - z0).abs() <= 1e-12 * z1.max(z0) {
        z1.sqrt()
    } else {
        (2.0 / 3.0) * (z1.powf(1.5) - z0.powf(1.5)) / (z1 - z0)
    }
}

/// The tangential law's memory for a tool moving in 3-D: where it first touched (dragged along while it
/// slides, for the Walton law), the axis of the first tangential motion and the incremental law's state
/// along it. Empty out of contact. See [`ContactModel::tangential_step`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TangentialMemory {
    anchor: Option<[f64; 3]>,
    axis: Option<[f64; 3]>,
    along: MindlinDeresiewicz,
}

impl ContactModel {
    /// Tangential force \[N\] of the Walton law at normal deformation z and tangential displacement δ_t
    /// \[m\], limited to the friction cone of the given normal force; `None` without a tangential law.
    /// Returns the force and whether the contact slides. (The incremental law needs the path:
    /// [`MindlinDeresiewicz::step`].)
    pub fn tangential_force(
        &self,
        z: f64,
        delta_t: f64,
        normal_force: f64,
    ) -> Result<Option<(f64, bool)>, ContactError> {
        let Some(t) = self.tangential else { return Ok(None) };
        let (z, delta_t, normal_force) =
            (finite("z", z)?, finite("δ_t", delta_t)?, finite("normal force", normal_force)?);
        if z <= 0.0 {
            return Ok(Some((0.0, false)));
        }
        let stick = t.stiffness * z.sqrt() * delta_t;
        let limit = t.friction * normal_force.max(0.0);
        Ok(Some(if stick.abs() <= limit { (stick, false) } else { (limit.copysign(stick), true) }))
    }

    /// The tangential force on the tool [N, world] and whether the contact slides, for a tool at
    /// `position` [m, world] pressed `z` deep with normal force `normal_force` along the unit `normal`;
    /// zero without a tangential law or out of contact. The displacement δ_t is the tool's tangential
    /// offset from where it first touched. Walton: while it slides, that anchor follows so that the spring
    /// holds exactly the friction limit. Mindlin–Deresiewicz: the incremental law along the axis of the
    /// first tangential motion, Walton's across it, the sum capped at μP. The simulated surface and the
    /// discrepancy workflow's wrench prediction both call this.
    pub fn tangential_step(
        &self,
        memory: &mut TangentialMemory,
        position: [f64; 3],
        normal: [f64; 3],
        z: f64,
        normal_force: f64,
    ) -> Result<([f64; 3], bool), ContactError> {
        let Some(t) = self.tangential.filter(|_| z > 0.0) else {
            *memory = TangentialMemory::default();
            return Ok(([0.0; 3], false));
        };
        let start = *memory.anchor.get_or_insert(position);
        let offset: [f64; 3] = std::array::from_fn(|i| position[i] - start[i]);
        let along_normal = dot(&offset, &normal);
        let delta: [f64; 3] = std::array::from_fn(|i| offset[i] - along_normal * normal[i]);
        let magnitude = dot(&delta, &delta).sqrt();
        match t.law {
            TangentialLaw::Walton => {
                if magnitude <= 0.0 {
                    return Ok(([0.0; 3], false));
                }
                let (ft, slides) = self.tangential_force(z, magnitude, normal_force)?.unwrap_or((0.0, false));
                let direction: [f64; 3] = std::array::from_fn(|i| delta[i] / magnitude);
                if slides && t.stiffness > 0.0 {
                    let stretch = t.friction * normal_force / (t.stiffness * z.sqrt());
                    memory.anchor =
                        Some(std::array::from_fn(|i| position[i] - along_normal * normal[i] - stretch * direction[i]));
                }
                Ok((std::array::from_fn(|i| -ft.abs() * direction[i]), slides))
            }
            TangentialLaw::MindlinDeresiewicz => {
                if memory.axis.is_none() && magnitude >= AXIS_MIN_MOTION {
                    memory.axis = Some(std::array::from_fn(|i| delta[i] / magnitude));
                }
                let axis = memory.axis.unwrap_or([0.0; 3]);
                let along = dot(&delta, &axis);
                let across: [f64; 3] = std::array::from_fn(|i| delta[i] - along * axis[i]);
                let (ft, mut slides) = memory.along.step(&t, z, along, normal_force)?;
                let walton = t.stiffness * z.sqrt();
                let mut force: [f64; 3] = std::array::from_fn(|i| -(ft * axis[i] + walton * across[i]));
                let limit = t.friction * normal_force.max(0.0);
                let norm = dot(&force, &force).sqrt();
                if norm > limit {
                    force = std::array::from_fn(|i| force[i] * limit / norm);
                    slides = true;
                }
                Ok((force, slides))
            }
        }
    }
}

/// The incremental law's axis is the direction of the first tangential motion at least this large [m]: a
/// stage's sub-micrometre jitter while it presses would otherwise fix the axis in a random direction and
/// leave the real motion across it, to the path-independent law (the arm as the snake paper's stage did that).
pub const AXIS_MIN_MOTION: f64 = 1e-6;

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|i| a[i] * b[i]).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    // The snake paper's magnitudes, in its units (N, mm): k_n 8.280 N/mm^1.5, k_t 3.7482 N/mm^1.5.
    const KN: f64 = 8.280;
    const KT: f64 = 3.7482;

    fn hertz(z: f64) -> f64 {
        KN * z.powf(1.5)
    }

    /// Drives the law along straight segments through `corners` of the (δ_n, δ_t) plane, `steps` steps
    /// each, and returns T at the end.
    fn along(law: &Tangential, corners: &[(f64, f64)], steps: usize) -> f64 {
        let mut md = MindlinDeresiewicz::default();
        let mut from = (0.0, 0.0);
        let mut t = 0.0;
        for &to in corners {
            for k in 1..=steps {
                let u = k as f64 / steps as f64;
                let (z, d) = (from.0 + u * (to.0 - from.0), from.1 + u * (to.1 - from.1));
                t = md.step(law, z, d, hertz(z)).unwrap().0;
            }
            from = to;
        }
        t
    }

    #[test]
    fn on_every_straight_path_it_is_walton() {
        // Rays at 2°…30° (the snake paper's linear paths) to 25 N: T = k_t √δ_n δ_t, however coarse the steps.
        let law = Tangential::mindlin_deresiewicz(KT, 0.9);
        for degrees in (2..=30).step_by(2) {
            let slope = (degrees as f64).to_radians().tan();
            let zn = (25.0 / KN).powf(2.0 / 3.0);
            for steps in [1, 7, 1000] {
                let t = along(&law, &[(zn, zn * slope)], steps);
                let walton = KT * zn.sqrt() * zn * slope;
                assert!((t - walton).abs() <= 1e-9 * walton, "{degrees}°, {steps} steps: {t} vs {walton}");
            }
        }
    }

    #[test]
    fn corner_paths_to_the_20_degree_ray_end_where_the_closed_forms_say() {
        // Without slip (μ very large): along α < β until δ_n matches, then tangentially:
        // T/T_W = 1.5 − 0.5 tan α / tan β; along α > β until δ_t matches, then normally: √(tan β / tan α).
        let law = Tangential::mindlin_deresiewicz(KT, 1e9);
        let tb = 20f64.to_radians().tan();
        for zn in [0.4, 1.2, 2.0] {
            let (dn, dt) = (zn, zn * tb);
            let walton = KT * dn.sqrt() * dt;
            for degrees in [10.0f64, 15.0, 16.0, 18.0, 19.0, 21.0, 22.0, 24.0, 25.0, 30.0] {
                let ta = degrees.to_radians().tan();
                let (corner, expected) =
                    if ta < tb { ((dn, dn * ta), 1.5 - 0.5 * ta / tb) } else { ((dt / ta, dt), (tb / ta).sqrt()) };
                let t = along(&law, &[corner, (dn, dt)], 50);
                assert!((t / walton - expected).abs() < 1e-9, "{degrees}° to {zn} mm: {} vs {expected}", t / walton);
            }
        }
        // 10° gives 1.258 and 30° 0.794 (the design note's numbers).
        assert!(((1.5 - 0.5 * 10f64.to_radians().tan() / tb) - 1.258).abs() < 5e-4);
        assert!(((tb / 30f64.to_radians().tan()).sqrt() - 0.794).abs() < 5e-4);
    }

    #[test]
    fn at_constant_normal_force_it_is_cattaneo_mindlin_and_unloads_by_masing() {
        let (mu, zn) = (0.8, 1.5);
        let p = hertz(zn);
        let law = Tangential::mindlin_deresiewicz(KT, mu);
        let mut md = MindlinDeresiewicz::default();
        md.step(&law, zn, 0.0, p).unwrap();
        // Cattaneo–Mindlin: T = μP[1 − (1 − k_t √δ_n δ_t / (μP))^{3/2}], full slip at δ_t = μP/(k_t √δ_n).
        let cattaneo = |d: f64| mu * p * (1.0 - (1.0 - (KT * zn.sqrt() * d / (mu * p)).min(1.0)).powf(1.5));
        let full_slip = mu * p / (KT * zn.sqrt());
        let peak = 0.6 * full_slip;
        let n = 20_000;
        for k in 1..=n {
            let d = peak * k as f64 / n as f64;
            let t = md.step(&law, zn, d, p).unwrap().0;
            assert!((t - cattaneo(d)).abs() <= 1e-5 * mu * p, "loading at {d}: {t} vs {}", cattaneo(d));
        }
        // Unloading from T* follows the loading curve doubled about it: T = T* − 2 f(Δ/2).
        let top = cattaneo(peak);
        for k in 1..=n {
            let back = 2.0 * peak * k as f64 / n as f64;
            let t = md.step(&law, zn, peak - back, p).unwrap().0;
            let masing = top - 2.0 * cattaneo(back / 2.0);
            assert!((t - masing).abs() <= 1e-5 * mu * p, "unloading by {back}: {t} vs {masing}");
        }
        // Back at −δ the loop meets the other direction's loading curve; reloading closes the loop at T*.
        assert!((md.force() + top).abs() <= 1e-4 * mu * p, "{} vs {}", md.force(), -top);
        for k in 1..=n {
            md.step(&law, zn, -peak + 2.0 * peak * k as f64 / n as f64, p).unwrap();
        }
        assert!((md.force() - top).abs() <= 1e-4 * mu * p, "closed at {} vs {top}", md.force());
        // Far beyond full slip it slides at μP.
        let (t, slides) = md.step(&law, zn, 3.0 * full_slip, p).unwrap();
        assert!(slides && (t - mu * p).abs() < 1e-12, "{t}");
    }

    #[test]
    fn the_force_never_leaves_the_friction_cone_and_clears_out_of_contact() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::SmallRng::seed_from_u64(7);
        let law = Tangential::mindlin_deresiewicz(KT, 0.5);
        let mut md = MindlinDeresiewicz::default();
        let (mut z, mut d) = (0.5f64, 0.0f64);
        for _ in 0..100_000 {
            z = (z + rng.random_range(-0.05..0.05)).clamp(0.0, 2.5);
            d += rng.random_range(-0.05..0.05);
            let p = hertz(z);
            let (t, _) = md.step(&law, z, d, p).unwrap();
            assert!(t.is_finite() && t.abs() <= 0.5 * p * (1.0 + 1e-12), "T {t} beyond μP {}", 0.5 * p);
            if z == 0.0 {
                assert_eq!(md, MindlinDeresiewicz::default());
            }
        }
    }

    #[test]
    fn non_finite_inputs_are_refused_and_change_nothing() {
        let law = Tangential::mindlin_deresiewicz(KT, 0.5);
        let mut md = MindlinDeresiewicz::default();
        md.step(&law, 1.0, 0.1, hertz(1.0)).unwrap();
        let before = md;
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(md.step(&law, bad, 0.1, 1.0).is_err());
            assert!(md.step(&law, 1.0, bad, 1.0).is_err());
            assert!(md.step(&law, 1.0, 0.1, bad).is_err());
        }
        assert_eq!(md, before);
    }

    #[test]
    fn the_law_is_named_in_the_model_file_and_walton_by_default() {
        let md = ContactModel::from_yaml(
            "kind: hertz_walton\nstiffness: 8.28\ntangential: {stiffness: 3.7482, friction: 0.9, law: mindlin_deresiewicz}\n",
        )
        .unwrap();
        assert_eq!(md.tangential, Some(Tangential::mindlin_deresiewicz(3.7482, 0.9)));
        assert!(md.to_yaml().contains("law: mindlin_deresiewicz"));
        let walton = ContactModel::from_yaml(
            "kind: hertz_walton\nstiffness: 8.28\ntangential: {stiffness: 3.7482, friction: 0.9}\n",
        )
        .unwrap();
        assert_eq!(walton.tangential, Some(Tangential::walton(3.7482, 0.9)));
        assert!(!walton.to_yaml().contains("law"));
        let err = ContactModel::from_yaml(
            "kind: hertz_walton\nstiffness: 8.28\ntangential: {stiffness: 3.7, friction: 0.9, law: coulomb}\n",
        )
        .unwrap_err();
        assert!(err.to_string().contains("mindlin_deresiewicz"), "{err}");
    }

    #[test]
    fn in_3d_the_incremental_law_matches_walton_on_a_straight_push_and_keeps_its_cone() {
        let walton = ContactModel { tangential: Some(Tangential::walton(KT, 0.9)), ..hertz_walton() };
        let md = ContactModel { tangential: Some(Tangential::mindlin_deresiewicz(KT, 0.9)), ..hertz_walton() };
        let normal = [0.0, 0.0, -1.0];
        let (mut mw, mut mm) = (TangentialMemory::default(), TangentialMemory::default());
        // Touch at the origin, then press 2 mm down while moving 0.7 mm along (1, 1)/√2: a straight ray.
        for k in 0..=200 {
            let u = k as f64 / 200.0;
            // Contact from the very first sample (a ray of the (δ_n, δ_t) plane starts at its origin).
            let (z, s) = (2.0 * u + 1e-15, 0.7 * u / 2f64.sqrt());
            let position = [s, s, -z];
            let p = hertz(z);
            let (fw, _) = walton.tangential_step(&mut mw, position, normal, z, p).unwrap();
            let (fm, _) = md.tangential_step(&mut mm, position, normal, z, p).unwrap();
            for i in 0..3 {
                assert!((fw[i] - fm[i]).abs() <= 1e-9 * (1.0 + fw[i].abs()), "{k}: {fw:?} vs {fm:?}");
            }
        }
        // Sideways far beyond the cone: both slide, at μP.
        let p = hertz(2.0);
        let (f, slides) = md.tangential_step(&mut mm, [5.0, -3.0, -2.0], normal, 2.0, p).unwrap();
        assert!(slides && (dot(&f, &f).sqrt() - 0.9 * p).abs() < 1e-9 * p, "{f:?}");
        // Out of contact the memory clears.
        md.tangential_step(&mut mm, [0.0, 0.0, 1.0], normal, 0.0, 0.0).unwrap();
        assert_eq!(mm, TangentialMemory::default());
    }

    #[test]
    fn sub_micrometre_jitter_does_not_fix_the_incremental_laws_axis() {
        // SI units: the snake paper's half-ball. Pressed 1 mm with 0.2 µm of sideways jitter across the coming
        // motion (a stage's tracking noise), then dragged 0.5 mm along x at that depth: the force along x
        // is the one-axis law's along the same (δ_n, δ_t) path, not Walton's.
        let (kn, kt) = (8.280 * crate::N_PER_MM_1_5, 3.7482 * crate::N_PER_MM_1_5);
        let md = ContactModel {
            tangential: Some(Tangential::mindlin_deresiewicz(kt, 0.9)),
            ..ContactModel::new(crate::Kind::HertzWalton, kn, 0.0).unwrap()
        };
        let law = md.tangential.unwrap();
        let normal = [0.0, 0.0, -1.0];
        let mut memory = TangentialMemory::default();
        let mut reference = MindlinDeresiewicz::default();
        let (mut f, mut t) = ([0.0; 3], 0.0);
        for k in 1..=2000 {
            let (z, x, y) = if k <= 1000 {
                (1e-3 * k as f64 / 1000.0, 0.0, 0.2e-6 * ((k - 1) as f64 * 0.37).sin())
            } else {
                (1e-3, 0.5e-3 * (k - 1000) as f64 / 1000.0, 0.0)
            };
            let p = kn * z.powf(1.5);
            f = md.tangential_step(&mut memory, [x, y, -z], normal, z, p).unwrap().0;
            t = reference.step(&law, z, x, p).unwrap().0;
        }
        let walton = kt * 1e-3f64.sqrt() * 0.5e-3;
        assert!((-f[0] - t).abs() < 1e-6 * t, "along x {} vs the one-axis law's {t}", -f[0]);
        assert!((t - walton).abs() > 0.1 * walton, "the path matters here: {t} vs Walton's {walton}");
    }

    fn hertz_walton() -> ContactModel {
        ContactModel::new(crate::Kind::HertzWalton, KN, 0.0).unwrap()
    }
}
