//! Surface effects written for the discrepancy corpus, not by the library: each in a functional form of
//! its own, integrated its own way, so that the workflow meets a surface its library describes only
//! nearly. crates/contact never calls this, and no tool reads it: it is the hidden truth of a recording.
//!
//! Added to the force of the surface's law (`SurfaceConfig::model`), on the deformation z and its rate ż:
//!
//! - **Prony series** (a generalized Maxwell solid of several branches): f += Σᵢ kᵢ (z⁺ − xᵢ),
//!   ẋᵢ = (z⁺ − xᵢ)/τᵢ, z⁺ = max(z, 0), each branch integrated exactly for a z⁺ linear within the step.
//! - **Fung's quasi-linear viscoelasticity** (Y. C. Fung, *Biomechanics: Mechanical Properties of Living
//!   Tissues*, ch. 7): the law's elastic force f_e(z) = f(z, ż = 0) is replaced by its hereditary integral
//!   f_r(t) = ∫ G(t − s) ḟ_e(s) ds with the reduced relaxation function G(t) = g_∞ + Σᵢ gᵢ e^{−t/τᵢ},
//!   G(0) = 1; recursively, hᵢ ← e^{−Δt/τᵢ} hᵢ + gᵢ τᵢ (1 − e^{−Δt/τᵢ}) Δf_e/Δt, f_r = g_∞ f_e + Σᵢ hᵢ.
//! - **Bouc–Wen hysteresis** (Y. K. Wen, "Method for random vibration of hysteretic systems", J. Eng.
//!   Mech. Div. 102 (1976)): f += F_w · w/w_max with ẇ = ż − β|ż||w|ⁿ⁻¹w − γż|w|ⁿ, β = γ, w_max =
//!   (1/(β + γ))^{1/n}; integrated in sub-steps of at most w_max/100 of travel; w returns to 0 out of
//!   contact.
//!
//! The total is kept at or above zero (a surface pushes, it does not pull).

/// One foreign surface effect and its parameters.
#[derive(Debug, Clone, PartialEq)]
pub enum ForeignEffect {
    /// Branches (stiffness kᵢ \[N/m\], time constant τᵢ \[s\]).
    Prony { branches: Vec<(f64, f64)> },
    /// Branches (gᵢ, τᵢ \[s\]) of the reduced relaxation function; g_∞ = 1 − Σ gᵢ.
    QuasiLinear { branches: Vec<(f64, f64)> },
    /// Largest hysteretic force F_w \[N\], the travel w_max at which it saturates \[m\], the exponent n.
    BoucWen { force: f64, travel: f64, exponent: f64 },
}

/// The foreign effects of a surface with their memory.
#[derive(Debug, Clone, Default)]
pub struct ForeignSurface {
    effects: Vec<ForeignEffect>,
    /// Per effect: the Prony strains xᵢ, the quasi-linear hᵢ, or the Bouc–Wen w.
    memory: Vec<Vec<f64>>,
    /// The last step's z⁺ and elastic force.
    last: Option<(f64, f64)>,
}

impl ForeignSurface {
    pub fn new(effects: Vec<ForeignEffect>) -> Result<Self, String> {
        for e in &effects {
            let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
            let ok = match e {
                ForeignEffect::Prony { branches } => {
                    branches.iter().all(|&(k, t)| finite(&[k, t]) && k >= 0.0 && t > 0.0)
                }
                ForeignEffect::QuasiLinear { branches } => {
                    branches.iter().all(|&(g, t)| finite(&[g, t]) && g >= 0.0 && t > 0.0)
                        && branches.iter().map(|b| b.0).sum::<f64>() <= 1.0
                }
                ForeignEffect::BoucWen { force, travel, exponent } => {
                    finite(&[*force, *travel, *exponent]) && *force >= 0.0 && *travel > 0.0 && *exponent >= 1.0
                }
            };
            if !ok {
                return Err(format!("foreign effect {e:?} is out of its range"));
            }
        }
        let memory = effects
            .iter()
            .map(|e| match e {
                ForeignEffect::Prony { branches } | ForeignEffect::QuasiLinear { branches } => {
                    vec![0.0; branches.len()]
                }
                ForeignEffect::BoucWen { .. } => vec![0.0],
            })
            .collect();
        Ok(Self { effects, memory, last: None })
    }

    pub fn is_empty(&self) -> bool {
        self.effects.is_empty()
    }

    /// The surface force with the foreign effects, from the law's force `law` and its elastic part
    /// `elastic` (f at ż = 0) at deformation z, rate ż, after a step of dt.
    pub fn step(&mut self, law: f64, elastic: f64, z: f64, zdot: f64, dt: f64) -> f64 {
        let u = z.max(0.0);
        let (u0, e0) = self.last.unwrap_or((u, elastic));
        self.last = Some((u, elastic));
        let mut f = law;
        for (effect, memory) in self.effects.iter().zip(self.memory.iter_mut()) {
            match effect {
                ForeignEffect::Prony { branches } => {
                    for (&(k, tau), x) in branches.iter().zip(memory.iter_mut()) {
                        *x = maxwell_strain(*x, u0, u, dt, tau);
                        f += k * (u - *x);
                    }
                }
                ForeignEffect::QuasiLinear { branches } => {
                    let rate = if dt > 0.0 { (elastic - e0) / dt } else { 0.0 };
                    let g_inf = 1.0 - branches.iter().map(|b| b.0).sum::<f64>();
                    let mut reduced = g_inf * elastic;
                    for (&(g, tau), h) in branches.iter().zip(memory.iter_mut()) {
                        let keep = (-dt / tau).exp();
                        *h = keep * *h + g * tau * (1.0 - keep) * rate;
                        reduced += *h;
                    }
                    f += reduced - elastic;
                }
                ForeignEffect::BoucWen { force, travel, exponent } => {
                    let w = &mut memory[0];
                    if z <= 0.0 {
                        *w = 0.0;
                        continue;
                    }
                    // β = γ with w_max = (1/(β + γ))^{1/n} = travel in units of travel: w is kept in them.
                    let n = *exponent;
                    let beta = 0.5;
                    let travel_step = zdot * dt / travel;
                    let substeps = (travel_step.abs() * 100.0).ceil().clamp(1.0, 1000.0) as usize;
                    let dx = travel_step / substeps as f64;
                    for _ in 0..substeps {
                        let a = w.abs();
                        *w += dx - beta * dx.abs() * a.powf(n - 1.0) * *w - beta * dx * a.powf(n);
                    }
                    f += force * *w;
                }
            }
        }
        f.max(0.0)
    }
}

/// A Maxwell branch's dashpot strain after dt, its spring's end moving linearly from u0 to u1: exactly,
/// x(dt) = u1 + (x0 − u0 + rτ) e^{−dt/τ} − rτ with r = (u1 − u0)/dt.
fn maxwell_strain(x0: f64, u0: f64, u1: f64, dt: f64, tau: f64) -> f64 {
    if dt <= 0.0 {
        return x0;
    }
    let r = (u1 - u0) / dt;
    u1 + (x0 - u0 + r * tau) * (-dt / tau).exp() - r * tau
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step of z held: each Prony branch relaxes as k e^{−t/τ} (the analytic relaxation modulus).
    #[test]
    fn a_held_step_relaxes_each_prony_branch_as_its_exponential() {
        let branches = vec![(100.0, 0.1), (50.0, 1.0), (20.0, 10.0)];
        let mut s = ForeignSurface::new(vec![ForeignEffect::Prony { branches: branches.clone() }]).unwrap();
        let dt = 1e-3;
        // A ramp to 1 cm over one step, then held (exact integration: the ramp's own relaxation is known).
        s.step(0.0, 0.0, 0.0, 0.0, dt);
        let z = 0.01;
        let mut f = s.step(0.0, 0.0, z, z / dt, dt);
        let first: f64 = branches.iter().map(|&(k, t)| k * z * t / dt * (1.0 - (-dt / t).exp())).sum();
        assert!((f - first).abs() < 1e-9 * first, "{f} {first}");
        for i in 1..=3000 {
            f = s.step(0.0, 0.0, z, 0.0, dt);
            let t = i as f64 * dt;
            let want: f64 =
                branches.iter().map(|&(k, tau)| k * z * tau / dt * (1.0 - (-dt / tau).exp()) * (-t / tau).exp()).sum();
            assert!((f - want).abs() < 1e-9 * first, "t {t}: {f} against {want}");
        }
    }

    /// Fung: the elastic force stepped and held falls to G(t) times it; loaded slowly it stays elastic.
    #[test]
    fn quasi_linear_relaxation_follows_the_reduced_relaxation_function() {
        let branches = vec![(0.2, 0.5), (0.1, 5.0)];
        let mut s = ForeignSurface::new(vec![ForeignEffect::QuasiLinear { branches: branches.clone() }]).unwrap();
        let dt = 1e-3;
        s.step(0.0, 0.0, 0.0, 0.0, dt);
        // The elastic force jumps to 100 N within one step, then holds.
        let mut f = s.step(100.0, 100.0, 0.01, 10.0, dt);
        let g = |t: f64| {
            0.7 + branches
                .iter()
                .map(|&(g, tau)| g * tau / dt * (1.0 - (-dt / tau).exp()) * (-t / tau).exp())
                .sum::<f64>()
        };
        assert!((f - 100.0 * g(0.0)).abs() < 1e-9, "{f}");
        for i in 1..=20_000 {
            f = s.step(100.0, 100.0, 0.01, 0.0, dt);
            assert!((f - 100.0 * g(i as f64 * dt)).abs() < 1e-9, "{i}: {f}");
        }
        assert!((f - 100.0 * 0.7).abs() < 0.1 * 100.0 * 0.1, "relaxed to g_∞: {f}");
    }

    /// Bouc–Wen: loading saturates at +F_w, reversing sweeps to −F_w over about twice the travel, and a
    /// loop's force on the way in exceeds the force on the way out at the same depth.
    #[test]
    fn bouc_wen_saturates_and_makes_a_loop() {
        let mut s =
            ForeignSurface::new(vec![ForeignEffect::BoucWen { force: 5.0, travel: 1e-3, exponent: 1.0 }]).unwrap();
        let dt = 1e-3;
        let v = 0.01;
        let mut inward = vec![];
        for i in 0..=1000 {
            let z = i as f64 * v * dt;
            inward.push(s.step(20.0, 20.0, z, v, dt) - 20.0);
        }
        assert!((inward[1000] - 5.0).abs() < 0.01, "saturated in: {}", inward[1000]);
        let mut outward = vec![];
        for i in (0..1000).rev() {
            let z = i as f64 * v * dt;
            outward.push(s.step(20.0, 20.0, z, -v, dt) - 20.0);
        }
        assert!((outward[800] + 5.0).abs() < 0.01, "saturated out: {}", outward[800]);
        assert!(inward[700] > outward[299], "no loop: {} {}", inward[700], outward[299]);
    }

    #[test]
    fn out_of_range_parameters_are_refused() {
        for e in [
            ForeignEffect::Prony { branches: vec![(1.0, 0.0)] },
            ForeignEffect::Prony { branches: vec![(f64::NAN, 1.0)] },
            ForeignEffect::QuasiLinear { branches: vec![(0.7, 1.0), (0.4, 2.0)] },
            ForeignEffect::BoucWen { force: 1.0, travel: f64::INFINITY, exponent: 1.0 },
        ] {
            assert!(ForeignSurface::new(vec![e.clone()]).is_err(), "{e:?}");
        }
    }
}
