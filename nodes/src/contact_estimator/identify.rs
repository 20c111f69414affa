//! Offline identification (`softcontact identify`): the contact estimator run over a whole recording
//! instead of a sliding window, with the frames the recording carries.

use nalgebra::Vector3;
use softcontact_contact::{ContactError, Fit, FitConfig, Kind, Sample};
use softcontact_msgs::geometry_msgs::{PoseStamped, TwistStamped, WrenchStamped};
use softcontact_msgs::tf2_msgs::TFMessage;

use crate::contact_estimator::{
    ContactEstimatorNode, EstimatorConfig, ForcePairing, MAX_READABLE_FORCE, ModelOut, Unpaired,
};
use crate::geometry;

/// Where the sensor's rotation in the tool frame came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FramesFrom {
    TfStatic,
    Urdf,
}

/// The force readings of a recording that were left out as not measurements (not finite, or beyond
/// [`MAX_READABLE_FORCE`]): how many, and the stamp of the first.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Unreadable {
    pub count: u64,
    pub first: Option<f64>,
}

impl Unreadable {
    pub fn note(&mut self, t: f64) {
        self.count += 1;
        self.first.get_or_insert(t);
    }

    /// The sentence that says them, `None` where there are none.
    pub fn sentence(&self) -> Option<String> {
        let first = match self.first {
            Some(t) if t.is_finite() => format!("the first stamped {t:.3} s"),
            _ => "the first with a stamp that is not finite".to_string(),
        };
        (self.count > 0).then(|| {
            format!(
                "{} force readings left out: not finite or beyond {MAX_READABLE_FORCE:e} N, not measurements ({first})",
                self.count
            )
        })
    }
}

/// Feeds a recording's messages, in the order they were recorded, to the estimator.
pub struct Identifier {
    estimator: ContactEstimatorNode,
    pairing: ForcePairing,
    frames: FramesFrom,
    tool_frame: String,
    pub readings: u64,
    pub unpaired: u64,
    pub unreadable: Unreadable,
    pub contact_time: Option<f64>,
    first_time: Option<f64>,
    /// How every kind is refitted at the estimated surface (the estimator's own fit settings).
    fit: FitConfig,
}

/// The result: every candidate's fit (cross-validated), the chosen model and the surface position.
#[derive(Debug, Clone)]
pub struct Identification {
    pub model: ModelOut,
    pub frames: FramesFrom,
    pub readings: u64,
    pub unpaired: u64,
    pub samples: usize,
    /// Seconds from the first force reading to the onset.
    pub contact_time: f64,
    /// Every candidate kind fitted at the estimated surface (`contact_position()`), cross-validated, in
    /// the order of `model.estimate.fits` (those are fitted at the force onset, the force-control paper's method). The
    /// selected kind's entry is `model.model`.
    pub at_surface: Vec<Fit>,
}

impl Identifier {
    /// `config.window` bounds the samples kept: give it at least the recording's duration over
    /// `config.sample_period` to fit every contact sample.
    pub fn new(config: EstimatorConfig, stale_after: f64) -> anyhow::Result<Self> {
        let (normal, fit) = (config.normal, config.fit);
        Ok(Self {
            estimator: ContactEstimatorNode::new(config)?,
            pairing: ForcePairing::new(crate::geometry::lwr4_tool_to_sensor().rotation, normal, stale_after)
                .ok_or_else(|| anyhow::anyhow!("the normal must be a non-zero direction"))?,
            frames: FramesFrom::Urdf,
            tool_frame: softcontact_dynamics::lwr4::TOOL_FRAME.into(),
            readings: 0,
            unpaired: 0,
            unreadable: Unreadable::default(),
            contact_time: None,
            first_time: None,
            fit,
        })
    }

    /// /tf_static: the sensor frame's rotation in the tool frame replaces the URDF's when it is there.
    pub fn tf_static(&mut self, msg: &TFMessage) {
        let sensor = softcontact_dynamics::lwr4::FT_SENSOR_FRAME;
        if let Some(r) = geometry::static_rotation(&[msg], &self.tool_frame, sensor) {
            self.pairing.geometry.tool_to_sensor = r;
            self.frames = FramesFrom::TfStatic;
        }
    }

    pub fn pose(&mut self, msg: &PoseStamped) {
        let (position, rotation) = geometry::pose_of(&msg.pose);
        self.pairing.pose(msg.header.stamp.as_secs_f64(), position, rotation);
    }

    pub fn twist(&mut self, msg: &TwistStamped) {
        self.pairing.twist(msg.header.stamp.as_secs_f64(), geometry::vector_of(&msg.twist.linear));
    }

    pub fn wrench(&mut self, msg: &WrenchStamped) -> Result<(), ContactError> {
        let t = msg.header.stamp.as_secs_f64();
        self.first_time.get_or_insert(t);
        let p = match self.pairing.force(t, geometry::vector_of(&msg.wrench.force)) {
            Ok(p) => p,
            Err(Unpaired::NoFreshPose) => {
                self.unpaired += 1;
                return Ok(());
            }
            Err(Unpaired::Unreadable) => {
                self.unreadable.note(t);
                return Ok(());
            }
        };
        self.reading(t, &p.position, &p.velocity, p.normal_force)
    }

    /// One reading already paired: the tool's position and velocity in the world and the normal force
    /// (a measurement table's row, its depth placed along the normal).
    pub fn reading(
        &mut self,
        t: f64,
        position: &Vector3<f64>,
        velocity: &Vector3<f64>,
        normal_force: f64,
    ) -> Result<(), ContactError> {
        self.first_time.get_or_insert(t);
        self.readings += 1;
        let out = self.estimator.update(t, position, velocity, normal_force)?;
        if out.in_contact && self.contact_time.is_none() {
            self.contact_time = Some(t);
        }
        Ok(())
    }

    /// Fits every candidate kind over all in-contact samples.
    pub fn finish(mut self) -> Result<Identification, ContactError> {
        let contact_time = self
            .contact_time
            .ok_or(ContactError::NotEnoughData { kind: "a contact (force above the onset threshold)" })?;
        let samples = self.estimator.samples();
        let model = self.estimator.refit()?;
        // The estimator's window, its deformation moved to the estimated surface.
        let moved: Vec<Sample> =
            self.estimator.window_samples().map(|s| Sample { z: s.z - model.offset, ..*s }).collect();
        let at_surface = surface_fits(&model.estimate.fits, &moved, &self.fit)?;
        Ok(Identification {
            at_surface,
            model,
            frames: self.frames,
            readings: self.readings,
            unpaired: self.unpaired,
            samples,
            contact_time: contact_time - self.first_time.unwrap_or(contact_time),
        })
    }
}

/// Each kind refitted to samples measured from the surface, with its onset fit as the prior (as the
/// estimator does for the selected kind).
fn surface_fits(at_onset: &[Fit], moved: &[Sample], cfg: &FitConfig) -> Result<Vec<Fit>, ContactError> {
    at_onset
        .iter()
        .map(|f| softcontact_contact::fit(f.kind, f.exponents, moved, Some((f.stiffness, f.damping)), cfg))
        .collect()
}

impl Identification {
    pub fn selected(&self) -> Kind {
        self.model.estimate.selected
    }

    pub fn contact_position(&self) -> Vector3<f64> {
        self.model.contact_position
    }
}

/// One reading of [`synthetic_pushes`]: what the driver and the F/T node would publish at time `t`.
#[derive(Debug, Clone)]
pub struct SyntheticReading {
    /// Seconds since the start.
    pub t: f64,
    pub joint_state: softcontact_msgs::sensor_msgs::JointState,
    pub pose: PoseStamped,
    pub twist: TwistStamped,
    pub wrench: WrenchStamped,
}

/// The force-control paper-style identification data made from a contact model alone, with an exactly known truth
/// (for the offline tools' tests and benchmarks): the tool faces down 5 mm above a horizontal surface
/// at height `surface_z`, approaches at 1 cm/s, then pushes at 1 Hz between 2 mm and `depth` of
/// deformation; `rate` readings a second, the force on the sensor in its own frame (through the URDF's
/// tool→sensor rotation) with Gaussian noise of `noise` N per axis. The model's effects (relaxation,
/// sensor bias, …) are in the readings, hidden from the tools that read them.
pub fn synthetic_pushes(
    model: &softcontact_contact::ContactModel,
    surface_z: f64,
    depth: f64,
    seconds: f64,
    rate: f64,
    noise: f64,
    seed: u64,
) -> anyhow::Result<Vec<SyntheticReading>> {
    let (approach, speed, (lo, hi)) = (0.005, 0.01, (0.002, depth));
    let touch = approach / speed;
    let pushes = |t: f64| {
        // Deformation z (positive into the surface) and its rate: the ramp, then 1 Hz pushes from z = 0
        // that swing between lo and hi (a smooth start: the cosine begins at its minimum).
        if t < touch {
            (speed * t - approach, speed)
        } else {
            let s = t - touch;
            let w = std::f64::consts::TAU;
            let blend = (s / 0.5).min(1.0);
            let mid = (lo + hi) / 2.0;
            let amp = (hi - lo) / 2.0;
            let target = mid - amp * (w * s).cos();
            (blend * target + (1.0 - blend) * speed * s, blend * amp * w * (w * s).sin() + (1.0 - blend) * speed)
        }
    };
    synthetic_readings(model, surface_z, pushes, seconds, rate, noise, seed)
}

/// As [`synthetic_pushes`], with the deformation z (positive into the surface) and its rate at time t
/// given by `profile`, e.g. a press and hold.
pub fn synthetic_readings(
    model: &softcontact_contact::ContactModel,
    surface_z: f64,
    profile: impl Fn(f64) -> (f64, f64),
    seconds: f64,
    rate: f64,
    noise: f64,
    seed: u64,
) -> anyhow::Result<Vec<SyntheticReading>> {
    use rand::{Rng, SeedableRng};
    use softcontact_msgs::builtin_interfaces::Time;
    use softcontact_msgs::geometry_msgs as geo;
    use softcontact_msgs::std_msgs::Header;

    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let mut gauss = move || {
        // Box-Muller.
        let (u, v): (f64, f64) = (rng.random_range(f64::EPSILON..1.0), rng.random());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let tool = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let to_sensor = (tool * crate::geometry::lwr4_tool_to_sensor().rotation).inverse();
    let n = (seconds * rate) as usize;
    let mut out = Vec::with_capacity(n);
    let mut effects = model.effect_state();
    for i in 0..n {
        let t = i as f64 / rate;
        let (z, zdot) = profile(t);
        // What the sensor reads of the surface, with the model's effects (the simulator's code).
        let f = model.step(&mut effects, z, zdot, 1.0 / rate)?.1;
        let stamp = Time::from_secs_f64(1.7e9 + t);
        let header = |frame: &str| Header { stamp, frame_id: frame.into() };
        let force_world = Vector3::new(0.0, 0.0, f);
        let fs = to_sensor * force_world + Vector3::new(gauss(), gauss(), gauss()) * noise;
        let v = |v: Vector3<f64>| geo::Vector3 { x: v.x, y: v.y, z: v.z };
        out.push(SyntheticReading {
            t,
            joint_state: softcontact_msgs::sensor_msgs::JointState {
                header: header(""),
                name: (1..=7).map(|j| format!("lwr_joint_{j}")).collect(),
                position: vec![0.0, 0.5, 0.0, -1.2, 0.0, 0.8 + z, 0.0],
                velocity: vec![0.0, 0.0, 0.0, 0.0, 0.0, zdot, 0.0],
                effort: vec![0.0, 10.0, 0.0, 5.0, 0.0, f * 0.1, 0.0],
            },
            pose: PoseStamped {
                header: header("world"),
                pose: geo::Pose {
                    position: geo::Point { x: 0.5, y: 0.0, z: surface_z - z },
                    orientation: geo::Quaternion { x: tool.i, y: tool.j, z: tool.k, w: tool.w },
                },
            },
            twist: TwistStamped {
                header: header("world"),
                twist: geo::Twist { linear: v(Vector3::new(0.0, 0.0, -zdot)), angular: v(Vector3::zeros()) },
            },
            wrench: WrenchStamped {
                header: header(softcontact_dynamics::lwr4::FT_SENSOR_FRAME),
                wrench: geo::Wrench { force: v(fs), torque: v(Vector3::zeros()) },
            },
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_contact::ContactModel;

    /// The selected kind refitted at the surface is exactly the estimator's model, whether the window
    /// holds every sample or only the last ones.
    #[test]
    fn the_selected_kind_at_the_surface_is_the_estimators_model() {
        let truth = ContactModel::new(Kind::HuntCrossley, 30_000.0, 40_000.0).unwrap();
        let readings = synthetic_pushes(&truth, 0.3, 0.03, 8.0, 1000.0, 0.2, 3).unwrap();
        for window in [300, 2000] {
            let fit = FitConfig { score_about_overall_mean: true, ..Default::default() };
            let mut identifier = Identifier::new(EstimatorConfig { window, fit, ..Default::default() }, 0.05).unwrap();
            for r in &readings {
                identifier.pose(&r.pose);
                identifier.twist(&r.twist);
                identifier.wrench(&r.wrench).unwrap();
            }
            let id = identifier.finish().unwrap();
            assert_eq!(id.at_surface.len(), id.model.estimate.fits.len());
            let selected = id.at_surface.iter().find(|f| f.kind == id.selected()).unwrap();
            assert_eq!(selected.model().unwrap(), id.model.model, "window {window}");
            assert_eq!(selected.samples, id.samples.min(window), "window {window}");
        }
    }
}
