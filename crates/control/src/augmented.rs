//! The augmented contact model inverted: the deformation that gives force f at the end of a move, and
//! keeps it during the hold, on a surface whose force has memory.
//!
//! The force-control paper inverts the static law, z = (f/k)^{1/a} (eq. 19). A surface that relaxes (Maxwell branches
//! ṡᵢ = kᵢ ż − sᵢ/τᵢ beside the elastic law, the discrepancy workflow's `viscoelastic_relaxation`) does
//! not hold that force: at the end of a move its branches still push, and during the hold they fade.
//! So the inverse carries the branches' states, driven by the measured deformation every tick, and
//! - **the end of a move** is found by shooting: the quintic from the present reference to a trial end
//!   is run through [`ContactModel::step_surface`] on a copy of the states, and the end is moved until
//!   the force at rest there is f (the branches' share is affine in the end, so the secant converges in a
//!   few steps);
//! - **the hold** solves [`ContactModel::force_at_rest`] = f with the states as they are now, each
//!   tick: the reference creeps deeper as the branches fade.
//!
//! An adhesion pulls while the deformation falls below the contact's deepest, in proportion to how far:
//! the hold asks for the deformation whose force, that pull counted, is f (the force still grows with z).
//! Hysteresis by the direction of motion scales the elastic force only while the surface moves, so it
//! acts through the simulated move; a surface offset drift moves the law's zero with time. The sensor's
//! named bias and drift are what a reading carries besides the surface force ([`AugmentedInverse::surface_reading`]).
//! Pure, and every per-tick method allocates nothing.

use softcontact_contact::{ContactError, ContactModel, EffectState, finite};

use crate::quintic::{Quintic, Reference};

/// The longest step of the shooting's simulated move [s]: the 0.15 s branch is resolved in 30 steps,
/// and a 2 s move costs 400 steps a trial.
const SHOOTING_STEP: f64 = 0.005;
/// Trials of the shooting and Newton steps of the hold before giving up.
const MAX_ITERATIONS: usize = 40;

#[derive(Debug, Clone)]
pub struct AugmentedInverse {
    model: ContactModel,
    state: EffectState,
}

impl AugmentedInverse {
    /// Whether `model` has effects the static inverse misses (anything but the base law).
    pub fn needed(model: &ContactModel) -> bool {
        !model.effects.is_empty()
    }

    pub fn new(model: ContactModel) -> Self {
        Self { state: model.effect_state(), model }
    }

    pub fn model(&self) -> &ContactModel {
        &self.model
    }

    /// Takes a re-estimated model of the same effects (in the same order) and keeps the branches' states;
    /// of other effects it starts from rest.
    pub fn adopt(&mut self, model: ContactModel) {
        let same = model.effects.len() == self.model.effects.len()
            && model.effects.iter().zip(&self.model.effects).all(|(a, b)| a.id() == b.id());
        self.model = model;
        if !same {
            self.reset();
        }
    }

    /// Forgets the branches' states (the contact was lost, or made anew).
    pub fn reset(&mut self) {
        let since_tare = self.state.since_tare;
        self.state = self.model.effect_state();
        self.state.since_tare = since_tare;
    }

    /// The sensor was tared: its drift counts from now.
    pub fn tared(&mut self) {
        self.state.tare();
    }

    /// Advances the states with the measured deformation z \[m\] from the model's surface and its rate
    /// [m/s] over dt \[s\]; returns the model's surface force \[N\].
    pub fn observe(&mut self, z: f64, zdot: f64, dt: f64) -> Result<f64, ContactError> {
        self.model.step_surface(&mut self.state, z, zdot, dt)
    }

    /// A normal force reading \[N\] without the sensor's named bias and drift: the surface force.
    pub fn surface_reading(&self, reading: f64) -> f64 {
        reading - self.model.sensor_offset(&self.state)
    }

    /// The deformation \[m\] to move to over the next `dt` seconds so that the surface force at rest there
    /// is `force`, the states as they are now (Newton on a monotone function, bracketed; dt = 0: at once).
    /// Allocates nothing.
    pub fn hold(&self, force: f64, guess: f64, dt: f64) -> Result<f64, ContactError> {
        let force = finite("force", force)?;
        if force < 0.0 {
            return Err(ContactError::NegativeForce(force));
        }
        let at = |z: f64| self.model.force_at_rest(&self.state, z, dt);
        // A bracket [lo, hi] with f(lo) ≤ force ≤ f(hi); f grows with z.
        let (mut lo, mut hi) = (0.0_f64.min(guess), guess.max(1e-6));
        let mut expansions = 0;
        while at(hi)?.0 < force {
            (lo, hi) = (hi, 2.0 * hi);
            expansions += 1;
            if expansions > 200 {
                return Err(ContactError::InvalidModel(format!("no deformation gives {force} N")));
            }
        }
        while at(lo)?.0 > force {
            lo = lo - (hi - lo);
            expansions += 1;
            if expansions > 200 {
                return Err(ContactError::InvalidModel(format!("no deformation gives {force} N")));
            }
        }
        let mut z = guess.clamp(lo, hi);
        for _ in 0..MAX_ITERATIONS {
            let (f, slope) = at(z)?;
            let error = f - force;
            if error.abs() <= 1e-9 * force.max(1.0) {
                return Ok(z);
            }
            if error > 0.0 {
                hi = z;
            } else {
                lo = z;
            }
            let newton = z - error / slope;
            z = if slope > 0.0 && newton > lo && newton < hi { newton } else { 0.5 * (lo + hi) };
            if hi - lo <= 1e-12 {
                return Ok(z);
            }
        }
        Ok(z)
    }

    /// The model's surface force \[N\] at the end of the quintic from `from` to rest at `end` in `duration`
    /// seconds, the states carried through it from now (a copy: the states are not changed).
    pub fn force_after_move(&self, from: &Reference, end: f64, duration: f64) -> Result<f64, ContactError> {
        let to = Reference { position: end, ..Default::default() };
        let quintic = Quintic::new(*from, to, duration)
            .ok_or_else(|| ContactError::InvalidModel(format!("no move to {end} m in {duration} s")))?;
        let steps = (duration / SHOOTING_STEP).ceil().max(1.0) as usize;
        let dt = duration / steps as f64;
        let mut state = self.state.clone();
        for i in 1..=steps {
            let r = quintic.at(dt * i as f64);
            self.model.step_surface(&mut state, r.position, r.velocity, dt)?;
        }
        Ok(self.model.force_at_rest(&state, end, 0.0)?.0)
    }

    /// The end \[m\] of the move from `from` over `duration` seconds after which the surface force at rest
    /// is `force`: secant steps on the simulated move, started from the hold's answer now.
    pub fn end_of_move(&self, from: &Reference, force: f64, duration: f64) -> Result<f64, ContactError> {
        let guess = self.hold(force, from.position.max(0.0), 0.0)?;
        let tolerance = 1e-6 * force.max(1.0);
        let mut a = (guess, self.force_after_move(from, guess, duration)? - force);
        if a.1.abs() <= tolerance {
            return Ok(a.0);
        }
        let nudge = 1e-4 * guess.abs().max(1e-3);
        let mut b = (guess + nudge, self.force_after_move(from, guess + nudge, duration)? - force);
        for _ in 0..MAX_ITERATIONS {
            if b.1.abs() <= tolerance {
                return Ok(b.0);
            }
            let slope = (b.1 - a.1) / (b.0 - a.0);
            if !(slope.is_finite() && slope > 0.0) {
                break;
            }
            let next = b.0 - b.1 / slope;
            a = b;
            b = (next, self.force_after_move(from, next, duration)? - force);
        }
        Err(ContactError::InvalidModel(format!("the augmented model gives no move to {force} N in {duration} s")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_contact::{Effect, Kind};

    /// A Kelvin–Voigt spring k with one Maxwell branch (k_m, τ): linear, so the force after any
    /// path has a closed form by convolution.
    fn standard_solid(k: f64, k_m: f64, tau: f64) -> ContactModel {
        let mut m = ContactModel::new(Kind::KelvinVoigt, k, 0.0).unwrap();
        m.effects = vec![Effect::ViscoelasticRelaxation { stiffness: k_m, time_constant: tau }];
        m
    }

    /// s(T) = k_m ∫₀ᵀ ż(t) e^{−(T−t)/τ} dt by Simpson's rule on 20 000 intervals (an independent
    /// quadrature of the Maxwell branch, not the model's stepping).
    fn branch_after_quintic(q: &Quintic, k_m: f64, tau: f64) -> f64 {
        let (n, t_end) = (20_000, q.duration());
        let h = t_end / n as f64;
        let g = |t: f64| q.at(t).velocity * (-(t_end - t) / tau).exp();
        let inner: f64 = (1..n).map(|i| g(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 }).sum();
        k_m * h / 3.0 * (g(0.0) + inner + g(t_end))
    }

    #[test]
    fn the_end_of_a_move_gives_the_force_by_the_branch_convolution() {
        let (k, k_m, tau) = (2000.0, 600.0, 0.15);
        let mut inverse = AugmentedInverse::new(standard_solid(k, k_m, tau));
        // The hand rests in contact at 1 cm (branches relaxed).
        for _ in 0..5000 {
            inverse.observe(0.01, 0.0, 1e-3).unwrap();
        }
        let from = Reference { position: 0.01, ..Default::default() };
        let end = inverse.end_of_move(&from, 50.0, 2.0).unwrap();
        let q = Quintic::rest_to_rest(0.01, end, 2.0).unwrap();
        let force = k * end + branch_after_quintic(&q, k_m, tau);
        assert!((force - 50.0).abs() < 1e-3, "force at the end {force} N for 50 N (end {end} m)");
        // The static inverse would stop short: the branch still pushes after a 2 s move.
        assert!(end < 50.0 / k - 1e-5, "end {end} vs static {}", 50.0 / k);
    }

    #[test]
    fn the_hold_keeps_the_force_while_the_branches_fade() {
        let (k, k_m, tau) = (2000.0, 600.0, 0.5);
        let model = standard_solid(k, k_m, tau);
        let mut inverse = AugmentedInverse::new(model.clone());
        // A quick press to 2 cm: the branch is loaded.
        for i in 1..=100 {
            let z = 0.02 * i as f64 / 100.0;
            inverse.observe(z, 0.2, 1e-3).unwrap();
        }
        let mut z = 0.02;
        let f = 30.0;
        // The model stepped on its own as the surface, fed the deformations the hold chooses.
        let mut surface = model.effect_state();
        for i in 1..=100 {
            model.step_surface(&mut surface, 0.02 * i as f64 / 100.0, 0.2, 1e-3).unwrap();
        }
        let mut branch_at_start = None;
        for _ in 0..3000 {
            let next = inverse.hold(f, z, 1e-3).unwrap();
            let rate = (next - z) / 1e-3;
            z = next;
            let read = model.step_surface(&mut surface, z, rate, 1e-3).unwrap();
            inverse.observe(z, rate, 1e-3).unwrap();
            assert!((read - f).abs() < 1e-6, "force {read} N during the hold");
            branch_at_start.get_or_insert(f - k * z);
        }
        // Held at k z + s = f, the branch ṡ = k_m ż − s/τ with ż = −ṡ/k fades with τ' = τ (1 + k_m/k).
        let slow = tau * (1.0 + k_m / k);
        let expected = branch_at_start.unwrap() * (-(3.0 - 1e-3) / slow).exp();
        let branch = f - k * z;
        assert!((branch / expected - 1.0).abs() < 0.01, "branch {branch} N, by hand {expected} N");
    }

    #[test]
    fn easing_off_an_adhesive_surface_goes_deeper_by_the_pull_it_will_feel() {
        // k z − F (z_peak − z)/(z_peak + δ) = f on the way out: linear, solved by hand.
        let (k, force, range) = (2000.0, 4.0, 0.005);
        let mut m = ContactModel::new(Kind::KelvinVoigt, k, 0.0).unwrap();
        m.effects = vec![Effect::Adhesion { force, range }];
        let mut inverse = AugmentedInverse::new(m.clone());
        for i in 1..=200 {
            inverse.observe(0.03 * i as f64 / 200.0, 0.15, 1e-3).unwrap();
        }
        let peak = 0.03;
        for f in [40.0, 10.0, 0.5, 0.0] {
            let z = inverse.hold(f, 0.02, 1e-3).unwrap();
            let by_hand = (f + force * peak / (peak + range)) / (k + force / (peak + range));
            assert!((z - by_hand).abs() < 1e-9, "{f} N: z {z} m, by hand {by_hand} m");
            assert!(z > f / k, "the pull asks for more deformation than the law alone");
        }
        // Pressing past the peak: the law alone again.
        assert!((inverse.hold(80.0, 0.03, 1e-3).unwrap() - 0.04).abs() < 1e-9);
    }

    #[test]
    fn the_sensor_bias_and_drift_come_out_of_a_reading() {
        let mut m = standard_solid(2000.0, 0.0, 1.0);
        m.effects = vec![Effect::SensorBias { offset: 0.5 }, Effect::SensorDrift { rate: 0.01 }];
        let mut inverse = AugmentedInverse::new(m);
        for _ in 0..1000 {
            inverse.observe(0.0, 0.0, 0.01).unwrap();
        }
        assert!((inverse.surface_reading(10.6) - 10.0).abs() < 1e-9);
        inverse.tared();
        assert!((inverse.surface_reading(10.5) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn a_mediums_drag_comes_out_of_a_reading_at_the_observed_rate_and_not_at_rest() {
        let mut m = standard_solid(2000.0, 0.0, 1.0);
        m.effects = vec![Effect::MediumDrag { damping: 4.0, tare_speed: 0.0 }];
        let mut inverse = AugmentedInverse::new(m);
        inverse.observe(0.005, 0.05, 1e-3).unwrap();
        assert!((inverse.surface_reading(10.2) - 10.0).abs() < 1e-9);
        inverse.observe(0.005, 0.0, 1e-3).unwrap();
        assert!((inverse.surface_reading(10.0) - 10.0).abs() < 1e-9);
        // The hold at rest is the law's alone: a drag pushes only while the hand moves.
        assert!((inverse.hold(10.0, 0.005, 1e-3).unwrap() - 0.005).abs() < 1e-9);
    }

    #[test]
    fn a_squeeze_films_drag_comes_out_of_a_reading_with_its_share_at_the_observed_gap() {
        let mut m = standard_solid(2000.0, 0.0, 1.0);
        m.effects = vec![Effect::SqueezeFilm { damping: 4.0, reach: 0.002 }];
        let mut inverse = AugmentedInverse::new(m);
        // One reach from the surface, closing in at 0.05 m/s: half of 4 N·s/m, 0.1 N, and no surface force.
        inverse.observe(-0.002, 0.05, 1e-3).unwrap();
        assert!(inverse.surface_reading(0.1).abs() < 1e-9);
        // In contact, the whole of it.
        inverse.observe(0.005, 0.05, 1e-3).unwrap();
        assert!((inverse.surface_reading(10.2) - 10.0).abs() < 1e-9);
        inverse.observe(0.005, 0.0, 1e-3).unwrap();
        assert!((inverse.surface_reading(10.0) - 10.0).abs() < 1e-9);
        assert!((inverse.hold(10.0, 0.005, 1e-3).unwrap() - 0.005).abs() < 1e-9);
    }

    #[test]
    fn hostile_inputs_are_errors_not_deformations() {
        let inverse = AugmentedInverse::new(standard_solid(2000.0, 600.0, 0.15));
        for f in [f64::NAN, f64::INFINITY, -1.0] {
            assert!(inverse.hold(f, 0.0, 1e-3).is_err(), "{f}");
            assert!(inverse.end_of_move(&Reference::default(), f, 2.0).is_err(), "{f}");
        }
        assert!(inverse.end_of_move(&Reference::default(), 10.0, f64::NAN).is_err());
        // No deformation within 2²⁰⁰ µm gives 1e300 N.
        assert!(inverse.hold(1e300, 0.0, 1e-3).is_err());
    }
}
