//! The residual of every wrench channel. The model predicts the whole wrench the sensor should read: the
//! normal force through [`ContactModel::step_surface`] and [`ContactModel::sense`] (as [`crate::simulate`]),
//! the tangential force through the model's tangential law and its memory
//! ([`ContactModel::tangential_step`], the simulated surface's own code), and the torque of that force,
//! applied at the tool point, about the sensor's origin. A model without a tangential law predicts no
//! tangential force, so the residual of the tangential channels then shows the load it misses.

use serde::Serialize;
use softcontact_contact::{ContactModel, TangentialMemory};

use crate::{DiscrepancyError, Phase, Series};

/// The rest of the recording the wrench prediction needs, one entry per sample of the [`Series`].
#[derive(Debug, Clone, PartialEq)]
pub struct Wrench {
    /// The contact normal n (unit, world): the series' z is along it.
    pub normal: [f64; 3],
    /// The tool point [m, world].
    pub position: Vec<[f64; 3]>,
    /// The sensor's orientation: the rotation sensor → world, by rows.
    pub sensor_rotation: Vec<[[f64; 3]; 3]>,
    /// The tool point, where the contact force acts, in the sensor frame \[m\].
    pub lever: [f64; 3],
    /// What the sensor read: Fx Fy Fz \[N\], Tx Ty Tz [N·m], in its frame (the hand's weight compensated).
    pub measured: Vec<[f64; 6]>,
}

/// The channels of [`Wrench::measured`]: name and unit.
pub const CHANNELS: [(&str, &str); 6] = [
    ("force_x", "N"),
    ("force_y", "N"),
    ("force_z", "N"),
    ("torque_x", "N·m"),
    ("torque_y", "N·m"),
    ("torque_z", "N·m"),
];

/// One channel's residual in contact, before (the refitted baseline) and after (the augmented model).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Channel {
    pub channel: &'static str,
    pub unit: &'static str,
    /// Standard deviation of the reading in free space about its mean; `None` without free space.
    pub noise_floor: Option<f64>,
    pub rms_before: f64,
    pub rms_after: f64,
    /// Largest |residual| after.
    pub max_after: f64,
}

impl Wrench {
    pub(crate) fn validate(&self, n: usize) -> Result<(), DiscrepancyError> {
        for (name, len) in [
            ("wrench position", self.position.len()),
            ("wrench sensor_rotation", self.sensor_rotation.len()),
            ("wrench measured", self.measured.len()),
        ] {
            if len != n {
                return Err(DiscrepancyError::InputLength { name, len, n });
            }
        }
        let norm = self.normal.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm.is_nan() || (norm - 1.0).abs() >= 1e-6 {
            return Err(DiscrepancyError::NotUnit { name: "wrench normal", norm });
        }
        for i in 0..n {
            let values =
                self.position[i].iter().chain(self.sensor_rotation[i].iter().flatten()).chain(&self.measured[i]);
            if !values.into_iter().all(|v| v.is_finite()) {
                return Err(DiscrepancyError::NonFinite { name: "wrench", index: i });
            }
        }
        if !self.lever.iter().all(|v| v.is_finite()) {
            return Err(DiscrepancyError::NonFinite { name: "lever", index: 0 });
        }
        Ok(())
    }
}

/// The wrench `model` predicts at every sample of `series` (which carries `wrench`), in the sensor frame.
pub fn predict_wrench(
    model: &ContactModel,
    series: &Series,
    wrench: &Wrench,
) -> Result<Vec<[f64; 6]>, DiscrepancyError> {
    let forces = crate::steps(model, series)?;
    let n = wrench.normal;
    let mut memory = TangentialMemory::default();
    (0..series.len())
        .map(|i| {
            let (surface, measured) = forces[i];
            let (tangential, _) = model.tangential_step(&mut memory, wrench.position[i], n, series.z[i], surface)?;
            // The force on the hand (world): the surface pushes against n, the sensor's effects on its normal
            // reading included; then in the sensor frame, and its torque at the tool point.
            let world: [f64; 3] = std::array::from_fn(|k| -measured * n[k] + tangential[k]);
            let r = &wrench.sensor_rotation[i];
            let f: [f64; 3] = std::array::from_fn(|c| (0..3).map(|k| r[k][c] * world[k]).sum());
            let l = wrench.lever;
            Ok([f[0], f[1], f[2], l[1] * f[2] - l[2] * f[1], l[2] * f[0] - l[0] * f[2], l[0] * f[1] - l[1] * f[0]])
        })
        .collect()
}

/// Every channel's residual in contact before and after, and its free-space noise.
pub(crate) fn channels(
    series: &Series,
    phases: &[Phase],
    wrench: &Wrench,
    before: &[[f64; 6]],
    after: &[[f64; 6]],
) -> Vec<Channel> {
    let contact: Vec<usize> = (0..series.len()).filter(|&i| phases[i].in_contact()).collect();
    let free: Vec<usize> = (0..series.len()).filter(|&i| !phases[i].in_contact()).collect();
    let rms = |p: &[[f64; 6]], c: usize| {
        (contact.iter().map(|&i| (wrench.measured[i][c] - p[i][c]).powi(2)).sum::<f64>() / contact.len().max(1) as f64)
            .sqrt()
    };
    CHANNELS
        .iter()
        .enumerate()
        .map(|(c, &(channel, unit))| {
            let noise_floor = (free.len() >= 20).then(|| {
                let mean = free.iter().map(|&i| wrench.measured[i][c]).sum::<f64>() / free.len() as f64;
                (free.iter().map(|&i| (wrench.measured[i][c] - mean).powi(2)).sum::<f64>() / (free.len() - 1) as f64)
                    .sqrt()
            });
            Channel {
                channel,
                unit,
                noise_floor,
                rms_before: rms(before, c),
                rms_after: rms(after, c),
                max_after: contact.iter().map(|&i| (wrench.measured[i][c] - after[i][c]).abs()).fold(0.0, f64::max),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use softcontact_contact::{Kind, Tangential};

    use super::*;

    /// A stuck contact pressed z deep and pulled δ sideways, by hand: the surface pushes k·z up (against
    /// n = −z), the Walton spring k_t·√z·δ back; the sensor hangs upside down (its z axis along n) with the
    /// tool point 0.1 m along its z axis.
    #[test]
    fn a_stuck_contact_reads_its_walton_force_and_torque_in_the_sensor_frame() {
        let (k, kt, z, delta) = (2000.0, 1.0e4, 0.01, 0.002);
        let mut model = ContactModel::new(Kind::KelvinVoigt, k, 0.0).unwrap();
        model.tangential = Some(Tangential::walton(kt, 0.8));
        // Touch at x = 0, press to z, then slide the tool δ along x while held at z.
        let t: Vec<f64> = (0..4).map(|i| i as f64 * 0.01).collect();
        let zs = vec![0.0, z, z, z];
        let x = [0.0, 0.0, delta, delta];
        let series = Series::new(t, zs.clone(), vec![0.0; 4], vec![0.0; 4]).unwrap();
        let flip = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]; // sensor → world: 180° about x
        let wrench = Wrench {
            normal: [0.0, 0.0, -1.0],
            position: (0..4).map(|i| [x[i], 0.0, -zs[i]]).collect(),
            sensor_rotation: vec![flip; 4],
            lever: [0.0, 0.0, 0.1],
            measured: vec![[0.0; 6]; 4],
        };
        let series = series.with_wrench(wrench.clone()).unwrap();
        let p = predict_wrench(&model, &series, &wrench).unwrap();
        // World force on the hand: (−k_t √z δ, 0, k z); in the sensor frame y and z flip.
        let (ft, fn_) = (kt * z.sqrt() * delta, k * z);
        let expected_force = [-ft, 0.0, -fn_];
        // τ = lever × F with lever (0, 0, 0.1): (−0.1 F_y, 0.1 F_x, 0).
        let expected = [expected_force[0], 0.0, expected_force[2], 0.0, 0.1 * expected_force[0], 0.0];
        for (c, e) in expected.iter().enumerate() {
            assert!((p[3][c] - e).abs() < 1e-9 * (1.0 + e.abs()), "channel {c}: {} vs {e}", p[3][c]);
        }
        // Before the slide no tangential force: only the normal one.
        assert!(p[1][0].abs() < 1e-12 && (p[1][2] + fn_).abs() < 1e-9, "{:?}", p[1]);
    }
}
