//! A flat soft surface: any contact model of crates/contact along its normal, and across it the model's
//! tangential law (Walton or Mindlin–Deresiewicz) with a friction cone and slip (`ContactModel::tangential_step`).

use nalgebra::Vector3;
use softcontact_contact::{ContactModel, EffectState, SensorInputs, TangentialMemory};

use crate::SimError;
use crate::foreign::{ForeignEffect, ForeignSurface};

/// Where the surface is and what it is made of.
#[derive(Debug, Clone)]
pub struct SurfaceConfig {
    /// A point of the undeformed top of the surface, in the world.
    pub point: Vector3<f64>,
    /// The contact direction n: the way the hand moves to compress the surface (unit, world).
    pub normal: Vector3<f64>,
    pub model: ContactModel,
    /// Effects written outside the library, added to the model's force ([`crate::foreign`]): the hidden
    /// truth of the discrepancy corpus's foreign cases; empty for every other surface.
    pub foreign: Vec<ForeignEffect>,
}

impl SurfaceConfig {
    /// A surface of `model` alone through `point` with contact direction `normal`.
    pub fn new(point: Vector3<f64>, normal: Vector3<f64>, model: ContactModel) -> Self {
        Self { point, normal, model, foreign: vec![] }
    }
}

/// The contact of one step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Contact {
    /// z = (r − surface point)·n \[m\]; positive in contact.
    pub deformation: f64,
    /// ż [m/s].
    pub rate: f64,
    /// The normal force the surface exerts, f ≥ 0 \[N\].
    pub normal_force: f64,
    /// What a sensor reads of the normal force with the model's sensor effects (bias, drift, crosstalk,
    /// delay) \[N\].
    pub measured_normal_force: f64,
    /// Total force on the hand, world \[N\].
    pub force: Vector3<f64>,
    /// The force a sensor reads, with the model's sensor effects, world \[N\].
    pub sensed_force: Vector3<f64>,
    pub sliding: bool,
}

/// A surface with its contact state (effects with memory, the tangential law's memory).
#[derive(Debug, Clone)]
pub struct Surface {
    config: SurfaceConfig,
    normal: Vector3<f64>,
    effects: EffectState,
    foreign: ForeignSurface,
    tangential: TangentialMemory,
}

impl Surface {
    pub fn new(config: SurfaceConfig) -> Result<Self, SimError> {
        let norm = config.normal.norm();
        if !(norm.is_finite() && norm > 0.0 && config.point.iter().all(|v| v.is_finite())) {
            return Err(SimError::Config("the surface needs a finite point and a non-zero normal".into()));
        }
        config.model.validate()?;
        let effects = config.model.effect_state();
        let foreign = ForeignSurface::new(config.foreign.clone()).map_err(SimError::Config)?;
        Ok(Self { normal: config.normal / norm, effects, foreign, tangential: TangentialMemory::default(), config })
    }

    pub fn config(&self) -> &SurfaceConfig {
        &self.config
    }

    /// Moves the undeformed top by `distance` along the normal \[m\] (the snake paper's creep of the specimen's
    /// zero between and during experiments: a hidden effect, set by the scenario, never read by the tools).
    pub fn creep(&mut self, distance: f64) {
        if distance.is_finite() {
            self.config.point += distance * self.normal;
        }
    }

    /// Contact of a tool at `position` moving at `velocity`, advancing the surface's memory by dt.
    pub fn contact(&mut self, position: &Vector3<f64>, velocity: &Vector3<f64>, dt: f64) -> Result<Contact, SimError> {
        let n = self.normal;
        let z = (position - self.config.point).dot(&n);
        let zd = velocity.dot(&n);
        let mut f = self.config.model.step_surface(&mut self.effects, z, zd, dt)?;
        if !self.foreign.is_empty() {
            let elastic = self.config.model.force(z, 0.0)?;
            f = self.foreign.step(f, elastic, z, zd, dt);
        }
        let (tangential, sliding) =
            self.config.model.tangential_step(&mut self.tangential, (*position).into(), n.into(), z, f.max(0.0))?;
        let force = -f * n + Vector3::from(tangential);
        // The sensor effects on the normal reading; the tangential load of this step feeds crosstalk. (A
        // model's unknown tool weight is carried by the sensor's load instead: see `Sim::new`.)
        let inputs = SensorInputs { tangential_force: tangential, gravity_change: 0.0 };
        let measured = self.config.model.sense(&mut self.effects, f, &inputs)?;
        let sensed_force = force - (measured - f) * n;
        Ok(Contact {
            deformation: z,
            rate: zd,
            normal_force: f,
            measured_normal_force: measured,
            force,
            sensed_force,
            sliding,
        })
    }
}
