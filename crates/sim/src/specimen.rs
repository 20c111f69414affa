//! The snake paper's specimen on its own bench: a gum-rubber half-ball (R = 12.7 mm) under a flat plate with
//! friction, read by a Nano17-like F/T sensor, pushed along paths of the (δ_n, δ_t) plane by an ideal
//! displacement stage — the paper's setup ("Frictional Compliance Model Development and
//! Experiments for Snake Robot Climbing", section IV), and the reference an arm-driven run is graded against.
//!
//! The contact is the model's: Hertz normal law and its tangential law (Walton or Mindlin–Deresiewicz,
//! crates/contact). The two errors the snake paper names are explicit, seeded parameters:
//! - **creep of the zero**: the ball's surface is still moving when an experiment starts, by `creep` [m]
//!   over the experiment (one draw per experiment, normal with standard deviation `creep_sd`), so the
//!   true normal approach is the stage's minus `creep · s`, s ∈ [0, 1] the progress along the path;
//! - **misalignment**: the sensor's axes are turned by ε (`misalignment` [rad]) in the loading plane from
//!   the pushing axes, so it reads F_n' = P cos ε − T sin ε and F_t' = T cos ε + P sin ε.
//!
//! Each experiment starts as the paper's did: the stage approaches from `approach` above the surface in
//! steps of `step` and takes as its zero the third reading above 0.03 N; the path's displacements are
//! measured from there. Readings carry white noise and are quantised to the sensor's resolution.

use rand::SeedableRng;
use rand::rngs::SmallRng;
use rand_distr::{Distribution, Normal};
use softcontact_contact::{ContactModel, LoadingPath, MindlinDeresiewicz, TangentialLaw};

use crate::SimError;

/// The specimen, its sensor and its bench.
#[derive(Debug, Clone)]
pub struct SpecimenConfig {
    /// Normal (Hertz) and tangential law of the half-ball on the plate.
    pub model: ContactModel,
    /// Sensor resolution \[N\] (a Nano17: 1/1280 N).
    pub resolution: f64,
    /// White noise of each force channel \[N\].
    pub noise: f64,
    /// Standard deviation of the creep of the zero over one experiment \[m\].
    pub creep_sd: f64,
    /// Sensor axes turned from the pushing axes in the loading plane \[rad\].
    pub misalignment: f64,
    /// Stage step along the path \[m\].
    pub step: f64,
    /// How far above the surface each experiment starts \[m\].
    pub approach: f64,
    pub seed: u64,
}

/// The reading that marks contact (the snake paper: the third reading above it is the zero).
pub const ZERO_THRESHOLD: f64 = 0.03;

impl SpecimenConfig {
    /// The snake paper's magnitudes: ≈ 25 N at ≈ 2 mm, a Nano17, a stage step of 5 µm; no creep, no
    /// misalignment, no noise (add them explicitly).
    pub fn seed_000(model: ContactModel, seed: u64) -> Self {
        SpecimenConfig {
            model,
            resolution: 1.0 / 1280.0,
            noise: 0.0,
            creep_sd: 0.0,
            misalignment: 0.0,
            step: 5e-6,
            approach: 50e-6,
            seed,
        }
    }
}

/// One sample of an experiment: the stage's displacements from the found zero \[m\] and the sensor's
/// reading in its own axes \[N\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchSample {
    pub normal_displacement: f64,
    pub tangential_displacement: f64,
    pub normal_force: f64,
    pub tangential_force: f64,
}

/// One experiment: its samples, and what it hid (for grading only: estimators never read it).
#[derive(Debug, Clone, PartialEq)]
pub struct BenchRun {
    pub samples: Vec<BenchSample>,
    /// The creep of the zero over this experiment \[m\].
    pub creep: f64,
    /// How far below the true surface the found zero lies \[m\] (the third reading above 0.03 N).
    pub zero_error: f64,
}

/// The bench: runs experiments one after another, each with its own draw of creep.
#[derive(Debug)]
pub struct SpecimenBench {
    config: SpecimenConfig,
    rng: SmallRng,
    noise: Normal<f64>,
    creep: Normal<f64>,
}

impl SpecimenBench {
    pub fn new(config: SpecimenConfig) -> Result<Self, SimError> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        if !(positive(config.resolution)
            && non_negative(config.noise)
            && non_negative(config.creep_sd)
            && config.misalignment.is_finite()
            && config.misalignment.abs() < 0.1
            && positive(config.step)
            && positive(config.approach))
        {
            return Err(SimError::Config(format!(
                "specimen bench: resolution and step > 0, noise and creep ≥ 0, |misalignment| < 0.1 rad, approach > 0 (got {config:?})"
            )));
        }
        if config.model.tangential.is_none() {
            return Err(SimError::Config("the specimen needs a tangential law".into()));
        }
        config.model.validate()?;
        Ok(SpecimenBench {
            rng: SmallRng::seed_from_u64(config.seed),
            noise: Normal::new(0.0, config.noise).expect("a finite, non-negative standard deviation"),
            creep: Normal::new(0.0, config.creep_sd).expect("a finite, non-negative standard deviation"),
            config,
        })
    }

    /// Runs one experiment along `path` (displacements from the zero the bench finds).
    pub fn run(&mut self, path: &LoadingPath) -> Result<BenchRun, SimError> {
        let c = &self.config;
        let law = c.model.tangential.expect("checked in new");
        let creep = self.creep.sample(&mut self.rng);
        let mut read = |p: f64, t: f64| sensor_reading(c, &self.noise, &mut self.rng, p, t);
        let total = path.length();
        // Find the zero: approach along the normal until the third reading above the threshold.
        let mut depth = -c.approach;
        let mut above = 0;
        while above < 3 {
            depth += c.step;
            if read(c.model.force(depth, 0.0)?, 0.0).0 > ZERO_THRESHOLD {
                above += 1;
            }
            if depth > 10.0 * c.approach + 1e-3 {
                return Err(SimError::Config("the bench found no surface".into()));
            }
        }
        let zero = depth;
        let mut md = MindlinDeresiewicz::default();
        let mut samples = Vec::with_capacity((total / c.step).ceil() as usize + path.waypoints.len() + 1);
        let (mut from, mut travelled) = ([0.0, 0.0], 0.0);
        for w in &path.waypoints {
            let length = (w[0] - from[0]).hypot(w[1] - from[1]);
            let steps = ((length / c.step).ceil() as usize).max(1);
            for k in 1..=steps {
                let u = k as f64 / steps as f64;
                let (dn, dt) = (from[0] + u * (w[0] - from[0]), from[1] + u * (w[1] - from[1]));
                let progress = if total > 0.0 { (travelled + u * length) / total } else { 1.0 };
                // The true approach: the stage's, from the found zero, less the creep so far.
                let z = zero + dn - creep * progress;
                let p = c.model.force(z, 0.0)?;
                let t = match law.law {
                    TangentialLaw::Walton => c.model.tangential_force(z, dt, p)?.map_or(0.0, |(t, _)| t),
                    TangentialLaw::MindlinDeresiewicz => md.step(&law, z, dt, p)?.0,
                };
                let (normal_force, tangential_force) = read(p, t);
                samples.push(BenchSample {
                    normal_displacement: dn,
                    tangential_displacement: dt,
                    normal_force,
                    tangential_force,
                });
            }
            travelled += length;
            from = *w;
        }
        Ok(BenchRun { samples, creep, zero_error: zero })
    }
}

/// The sensor's reading of normal force p and tangential force t: turned by the misalignment, noisy,
/// quantised.
fn sensor_reading(c: &SpecimenConfig, noise: &Normal<f64>, rng: &mut SmallRng, p: f64, t: f64) -> (f64, f64) {
    let (s, co) = c.misalignment.sin_cos();
    let q = c.resolution;
    let mut channel = |f: f64| ((f + noise.sample(rng)) / q).round() * q;
    let normal = channel(p * co - t * s);
    (normal, channel(t * co + p * s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_contact::{Kind, Tangential, seed_000_experiments};

    use softcontact_contact::N_PER_MM_1_5 as PER_MM;

    fn model(law: Tangential) -> ContactModel {
        let mut m = ContactModel::new(Kind::HertzWalton, 8.280 * PER_MM, 0.0).unwrap();
        m.tangential = Some(Tangential { stiffness: 3.7482 * PER_MM, ..law });
        m
    }

    #[test]
    fn an_ideal_bench_reads_the_law_from_a_zero_just_below_the_surface() {
        let m = model(Tangential::mindlin_deresiewicz(0.0, 0.9));
        let mut bench = SpecimenBench::new(SpecimenConfig::seed_000(m.clone(), 1)).unwrap();
        let paths = seed_000_experiments(&m, 2e-3).unwrap();
        let ray = paths.iter().find(|p| p.angle == 14.0).unwrap();
        let run = bench.run(ray).unwrap();
        // The third reading above 0.03 N: 0.03 N is 23.6 µm deep (8.28 N/mm^1.5), read in steps of 5 µm
        // from 50 µm above, so readings above it begin at 25 µm and the third is at 35 µm.
        assert!((run.zero_error - 35e-6).abs() < 1e-12, "zero {} m below the surface", run.zero_error);
        let last = run.samples.last().unwrap();
        let z = last.normal_displacement + run.zero_error;
        let p = 8.280 * PER_MM * z.powf(1.5);
        assert!((last.normal_force - p).abs() <= 1.0 / 2560.0 + 1e-12, "{} vs {p}", last.normal_force);
        // Pressed 35 µm straight down first, then along the ray from there: without slip (dT/dP = 0.11 <
        // μ on it) T = ∫ (3/2) k_t √z dδ_t = k_t tan 14° (z^{3/2} − z0^{3/2}), z0 the found zero.
        let expected = 3.7482 * PER_MM * 14f64.to_radians().tan() * (z.powf(1.5) - run.zero_error.powf(1.5));
        assert!((last.tangential_force - expected).abs() <= 1.0 / 2560.0 + 1e-9, "{last:?} vs {expected}");
        assert_eq!(run.creep, 0.0);
    }

    #[test]
    fn a_misaligned_sensor_reads_the_rotated_forces() {
        // The snake paper's sizes: at 2 mm on the 20° ray, 1° of misalignment adds ≈ 0.41 N to T.
        let m = model(Tangential::walton(0.0, 0.9));
        let eps = 1f64.to_radians();
        let mut aligned =
            SpecimenBench::new(SpecimenConfig { resolution: 1e-9, ..SpecimenConfig::seed_000(m.clone(), 3) }).unwrap();
        let mut turned = SpecimenBench::new(SpecimenConfig {
            resolution: 1e-9,
            misalignment: eps,
            ..SpecimenConfig::seed_000(m.clone(), 3)
        })
        .unwrap();
        let path = LoadingPath {
            family: softcontact_contact::Family::Linear,
            angle: 20.0,
            point: None,
            repeat: 0,
            waypoints: vec![[2e-3, 2e-3 * 20f64.to_radians().tan()]],
        };
        let a = *aligned.run(&path).unwrap().samples.last().unwrap();
        let t = *turned.run(&path).unwrap().samples.last().unwrap();
        let (p, tt) = (a.normal_force, a.tangential_force);
        assert!((t.tangential_force - (tt * eps.cos() + p * eps.sin())).abs() < 1e-6);
        assert!((t.normal_force - (p * eps.cos() - tt * eps.sin())).abs() < 1e-6);
        assert!((t.tangential_force - tt - 0.41).abs() < 0.02, "adds {} N", t.tangential_force - tt);
    }

    #[test]
    fn creep_lowers_the_normal_force_by_the_hertz_slope() {
        // ΔP ≈ 1.5 k_n √δ_n e: 10 µm of creep at 2 mm costs ≈ 0.18 N (the snake paper's Table I error is 0.168 N).
        let m = model(Tangential::walton(0.0, 0.9));
        let mut bench = SpecimenBench::new(SpecimenConfig {
            creep_sd: 10e-6,
            resolution: 1e-9,
            ..SpecimenConfig::seed_000(m.clone(), 11)
        })
        .unwrap();
        let path = LoadingPath {
            family: softcontact_contact::Family::Normal,
            angle: 0.0,
            point: None,
            repeat: 0,
            waypoints: vec![[2e-3, 0.0]],
        };
        let mut creeps = Vec::new();
        for _ in 0..200 {
            let run = bench.run(&path).unwrap();
            let last = run.samples.last().unwrap();
            let z = last.normal_displacement + run.zero_error;
            let loss = 8.280 * PER_MM * z.powf(1.5) - last.normal_force;
            let slope = 1.5 * 8.280 * PER_MM * z.sqrt();
            assert!(
                (loss - slope * run.creep).abs() < 0.01 * slope * run.creep.abs() + 1e-6,
                "{loss} for {}",
                run.creep
            );
            creeps.push(run.creep);
        }
        let sd = (creeps.iter().map(|c| c * c).sum::<f64>() / creeps.len() as f64).sqrt();
        assert!((sd - 10e-6).abs() < 1.5e-6, "creep draws with sd {sd}");
        assert!((1.5 * 8.280 * PER_MM * 2e-3f64.sqrt() * 10e-6 - 0.18).abs() < 0.01);
    }

    #[test]
    fn bad_configurations_are_refused() {
        let m = model(Tangential::walton(0.0, 0.9));
        for bad in [
            SpecimenConfig { resolution: 0.0, ..SpecimenConfig::seed_000(m.clone(), 0) },
            SpecimenConfig { noise: f64::NAN, ..SpecimenConfig::seed_000(m.clone(), 0) },
            SpecimenConfig { creep_sd: -1e-6, ..SpecimenConfig::seed_000(m.clone(), 0) },
            SpecimenConfig { misalignment: f64::INFINITY, ..SpecimenConfig::seed_000(m.clone(), 0) },
            SpecimenConfig { step: 1e300 * 0.0, ..SpecimenConfig::seed_000(m.clone(), 0) },
            SpecimenConfig {
                model: ContactModel::new(Kind::HertzWalton, 1.0, 0.0).unwrap(),
                ..SpecimenConfig::seed_000(m.clone(), 0)
            },
        ] {
            assert!(SpecimenBench::new(bad).is_err());
        }
    }
}
