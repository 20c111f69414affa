//! Test data written independently of the crate: closed-form force laws and the force-control paper's-like trajectories.
#![allow(dead_code)]

use rand::Rng;
use rand_distr::{Distribution, Normal};
use softcontact_contact::{Kind, Sample};

/// The named laws, written out by hand (not through the crate): f = k zᵃ + λ zᵇ ż.
pub fn closed_form(kind: Kind, k: f64, l: f64, z: f64, zd: f64) -> f64 {
    if z <= 0.0 {
        return 0.0;
    }
    let f = match kind {
        Kind::KelvinVoigt => k * z + l * zd,
        Kind::HuntCrossley | Kind::HertzWalton => k * z.powf(1.5) + l * z.powf(1.5) * zd,
        Kind::AzadFeatherstone => k * z.powf(1.5) + l * z.sqrt() * zd,
        Kind::General => unreachable!(),
    };
    f.max(0.0)
}

/// The force-control paper's identification trajectory in deformation coordinates, sampled every 10 ms: a ramp from
/// 4 cm above the surface to the middle depth, 1 Hz sine pushes between 0 and `depth`, a ramp back.
/// Returns (z, ż) pairs.
pub fn identification(depth: f64, cycles: usize) -> Vec<(f64, f64)> {
    let dt = 0.01;
    let (start, mid, amp) = (-0.04, depth / 2.0, depth / 2.0);
    let ramp = 2.0;
    let w = 2.0 * std::f64::consts::PI;
    let mut out = Vec::new();
    let total = 2.0 * ramp + cycles as f64;
    let mut t = 0.0;
    while t < total {
        let (z, zd) = if t < ramp {
            (start + (mid - start) * t / ramp, (mid - start) / ramp)
        } else if t < ramp + cycles as f64 {
            let s = t - ramp;
            (mid + amp * (w * s).sin(), amp * w * (w * s).cos())
        } else {
            let s = t - ramp - cycles as f64;
            (mid + (start - mid) * s / ramp, (start - mid) / ramp)
        };
        out.push((z, zd));
        t += dt;
    }
    out
}

/// In-contact samples of a law along a trajectory, with Gaussian force noise of `noise` N.
pub fn samples(kind: Kind, k: f64, l: f64, traj: &[(f64, f64)], noise: f64, rng: &mut impl Rng) -> Vec<Sample> {
    let normal = Normal::new(0.0, noise.max(1e-300)).unwrap();
    traj.iter()
        .filter(|(z, _)| *z > 0.0)
        .map(|&(z, zd)| Sample {
            z,
            zdot: zd,
            f: closed_form(kind, k, l, z, zd) + if noise > 0.0 { normal.sample(rng) } else { 0.0 },
        })
        .collect()
}

/// Stiffness giving `force` at `depth`, and damping giving `ratio` of it at the sine's peak rate.
pub fn parameters(kind: Kind, depth: f64, force: f64, ratio: f64) -> (f64, f64) {
    let a = if kind == Kind::KelvinVoigt { 1.0 } else { 1.5 };
    let k = force / depth.powf(a);
    let (z, zd) = (depth / 2.0, depth / 2.0 * 2.0 * std::f64::consts::PI);
    let b = match kind {
        Kind::KelvinVoigt => 0.0,
        Kind::AzadFeatherstone => 0.5,
        _ => 1.5,
    };
    let l = ratio * k * z.powf(a) / (z.powf(b) * zd);
    (k, l)
}
