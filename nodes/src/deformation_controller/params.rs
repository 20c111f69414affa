//! The `deformation_controller` node's parameters (config/deformation_controller.yaml), declared once in
//! [`NodeParams::declare`](crate::runtime::params::NodeParams), and the law's configuration made from them.

use nalgebra::Vector3;
use softcontact_contact::{ContactModel, OnsetConfig};
use softcontact_control::DeformationGains;
use softcontact_dynamics::ArmEffects;

use super::{ControllerConfig, EXPONENT_RANGE};

/// When the controller takes a new model from the estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelUpdate {
    /// The newest model is adopted when the next force command arrives (the force-control paper: once per cycle).
    OnCommand,
    /// Every model is adopted when it arrives, and the standing command re-planned through it.
    Continuous,
}

/// The `deformation_controller` node's parameters (config/deformation_controller.yaml). What each means and the values it takes are
/// declared once, in `declare` (`NodeParams`), which checks them at start-up and describes them over ROS.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    pub normal: [f64; 3],
    pub deformation_frequency: f64,
    pub lateral_gains: [f64; 2],
    pub orientation_gains: [f64; 2],
    pub posture_stiffness: [f64; 7],
    pub posture_damping: [f64; 7],
    pub approach_speed: f64,
    pub max_approach: f64,
    pub onset_threshold: f64,
    pub onset_confirm: usize,
    pub torque_rate: f64,
    pub max_force: f64,
    pub max_deformation: f64,
    pub contact_lost_below: f64,
    pub force_limit: f64,
    pub max_lift: f64,
    pub max_deformation_rate: f64,
    pub move_duration: [f64; 2],
    pub max_surface_offset: f64,
    pub restart_after: f64,
    pub model_update: ModelUpdate,
    pub retarget_duration: f64,
    pub initial_model: ContactModel,
    /// Where the undeformed surface lies in the world, if known before contact (the discrepancy
    /// workflow's placement): the first force command in contact places `initial_model`'s surface there.
    pub initial_surface: Option<[f64; 3]>,
    pub state_rate: f64,
    pub stale_after: f64,
    pub force_check_tolerance: f64,
    pub force_check_relative: f64,
    pub force_check_impulse: f64,
    pub dead_after: f64,
    pub service_mapping: String,
    pub arm_effects: ArmEffects,
    pub use_sim_time: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self::from_law(&ControllerConfig::lwr4(250.0, 0.06))
    }
}

impl Params {
    /// The node's defaults with the law's configuration `c` (what [`Params::controller_config`] gives
    /// back: `c`'s control period and joint torque limits are the LWR IV's).
    pub fn from_law(c: &ControllerConfig) -> Self {
        Self {
            normal: c.normal.into(),
            deformation_frequency: c.gains.stiffness.sqrt(),
            lateral_gains: c.lateral.into(),
            orientation_gains: c.orientation.into(),
            posture_stiffness: c.posture_stiffness,
            posture_damping: c.posture_damping,
            approach_speed: c.approach_speed,
            max_approach: c.max_approach,
            onset_threshold: c.onset.threshold,
            onset_confirm: c.onset.confirm,
            torque_rate: c.limits.torque_rate,
            max_force: c.limits.max_force,
            max_deformation: c.limits.max_deformation,
            contact_lost_below: c.limits.contact_lost_below,
            force_limit: c.limits.force_limit,
            max_lift: c.limits.max_lift,
            max_deformation_rate: c.limits.max_deformation_rate,
            move_duration: c.limits.move_duration.into(),
            max_surface_offset: c.max_surface_offset,
            restart_after: c.restart_after,
            model_update: ModelUpdate::OnCommand,
            retarget_duration: 0.5,
            initial_model: ContactModel::new(softcontact_contact::Kind::KelvinVoigt, 5_000.0, 0.0)
                .expect("a valid model"),
            initial_surface: None,
            state_rate: 100.0,
            stale_after: 0.05,
            force_check_tolerance: 20.0,
            force_check_relative: 0.25,
            force_check_impulse: 0.5,
            dead_after: 2.0,
            service_mapping: "cyclone".into(),
            arm_effects: c.arm,
            use_sim_time: false,
        }
    }

    /// The law's configuration these parameters give.
    pub fn controller_config(&self) -> ControllerConfig {
        let mut c = ControllerConfig::lwr4(self.max_force, self.max_deformation);
        c.normal = self.normal.into();
        c.gains = DeformationGains::critically_damped(self.deformation_frequency);
        c.lateral = self.lateral_gains.into();
        c.orientation = self.orientation_gains.into();
        c.posture_stiffness = self.posture_stiffness;
        c.posture_damping = self.posture_damping;
        c.approach_speed = self.approach_speed;
        c.max_approach = self.max_approach;
        c.onset = OnsetConfig { threshold: self.onset_threshold, confirm: self.onset_confirm };
        c.limits.torque_rate = self.torque_rate;
        c.limits.contact_lost_below = self.contact_lost_below;
        c.limits.force_limit = self.force_limit;
        c.limits.max_lift = self.max_lift;
        c.limits.max_deformation_rate = self.max_deformation_rate;
        c.limits.move_duration = self.move_duration.into();
        c.max_surface_offset = self.max_surface_offset;
        c.restart_after = self.restart_after;
        c.arm = self.arm_effects;
        c
    }
}

impl crate::runtime::params::NodeParams for Params {
    /// Every number has a physical range: a value outside it refuses to start the node.
    fn declare(&self, d: &mut crate::runtime::params::Declarations) {
        self.declare_law(d);
        self.declare_limits(d);
        self.declare_node(d);
        self.declare_models(d);
        d.use_sim_time();
    }
}

impl Params {
    /// The parameters of the law: its gains, the approach and the onset.
    fn declare_law(&self, d: &mut crate::runtime::params::Declarations) {
        d.direction(
            "normal",
            self.normal,
            "contact direction n in the world (the hand compresses the surface along it)",
        );
        d.within(
            "deformation_frequency",
            self.deformation_frequency,
            (5.0, 200.0),
            "natural frequency of the critically damped deformation law (k_z = ω², k_ż = 2ω) [rad/s]",
        );
        d.each("lateral_gains", &self.lateral_gains, (0.0, 1e4), "PD gains across the surface [1/s², 1/s]");
        d.each(
            "orientation_gains",
            &self.orientation_gains,
            (0.0, 1e4),
            "PD gains of the hand's orientation [1/s², 1/s]",
        );
        d.each(
            "posture_stiffness",
            &self.posture_stiffness,
            (0.0, 1e3),
            "null-space joint impedance holding the initial posture [N·m/rad]",
        );
        d.each("posture_damping", &self.posture_damping, (0.0, 1e2), "null-space joint damping [N·m·s/rad]");
        d.above("approach_speed", self.approach_speed, (0.0, 0.05), "descent speed before contact [m/s]");
        d.above(
            "max_approach",
            self.max_approach,
            (0.0, 0.5),
            "farthest the approach goes without finding a surface; then the hand holds [m]",
        );
        d.onset(self.onset_threshold, self.onset_confirm);
    }

    /// The parameters of the limits every command and torque is checked against.
    fn declare_limits(&self, d: &mut crate::runtime::params::Declarations) {
        d.above("torque_rate", self.torque_rate, (0.0, 1e5), "largest torque rate commanded [N·m/s]");
        d.above("max_force", self.max_force, (0.0, 500.0), "largest force a command may ask for [N]");
        d.above("max_deformation", self.max_deformation, (0.0, 0.2), "largest deformation commanded [m]");
        d.above("contact_lost_below", self.contact_lost_below, (0.0, self.max_force / 4.0), "while a force is commanded, contact counts as lost below this force: the hand holds [N] (at most max_force / 4)");
        d.above(
            "force_limit",
            self.force_limit,
            (self.max_force, 2.0 * self.max_force),
            "measured normal force above which the controller backs off [N] (above max_force, at most twice it)",
        );
        d.above("max_lift", self.max_lift, (0.0, 0.2), "largest lift above the surface a command may ask for [m]");
        d.above(
            "max_deformation_rate",
            self.max_deformation_rate,
            (0.0, 0.5),
            "fastest a move may compress or lift [m/s]",
        );
        let [shortest, longest] = self.move_duration;
        let ordered =
            shortest.is_finite() && longest.is_finite() && 0.01 <= shortest && shortest < longest && longest <= 3600.0;
        let durations =
            if ordered { Ok(()) } else { Err(format!("{:?} is not [shortest, longest]", self.move_duration)) };
        d.rule(
            "move_duration",
            durations,
            "[shortest, longest] within [0.01, 3600] s, shortest < longest",
            "shortest and longest move a command may ask for [s]",
        );
        d.within(
            "retarget_duration",
            self.retarget_duration,
            (shortest, longest),
            "re-planning time of the continuous policy [s] (within move_duration)",
        );
        d.above(
            "max_surface_offset",
            self.max_surface_offset,
            (0.0, 0.05),
            "farthest an estimated surface may lie from the measured onset; a model placing it further is refused [m]",
        );
    }

    /// The parameters of the node: its rates, staleness, the force check, liveness and the model policy.
    fn declare_node(&self, d: &mut crate::runtime::params::Declarations) {
        d.above("state_rate", self.state_rate, (0.0, 1000.0), "/deformation_controller/state rate [Hz]");
        d.above(
            "stale_after",
            self.stale_after,
            (0.0, 1.0),
            "no command is sent while the force reading is older than this: the driver then holds [s]",
        );
        d.above("restart_after", self.restart_after, (self.stale_after, 10.0), "joint states interrupted this long mean a new KRC session or a moved arm: approach again [s] (above stale_after)");
        // The check is never off: the KRC's estimate is good to a few newtons with the tool load set.
        d.above("force_check_tolerance", self.force_check_tolerance, (1.0, 100.0), "the F/T sensor and the arm's joint torque sensors (the KRC's estExtJntTrq) may disagree on the contact force by this [N] ...");
        d.above(
            "force_check_relative",
            self.force_check_relative,
            (0.0, 1.0),
            "... plus this share of the smaller force",
        );
        d.above(
            "force_check_impulse",
            self.force_check_impulse,
            (0.0, 5.0),
            "the disagreement beyond, summed over time, holds the arm at this impulse until a new KRC session [N·s]",
        );
        crate::runtime::liveness::declare_dead_after(
            d,
            self.dead_after,
            self.restart_after,
            "/lwr/joint_states silent this long after they flowed: the driver or the middleware is dead, exit with an error [s] (above restart_after)",
        );
        d.service_mapping(
            &self.service_mapping,
            "service mapping of the peers' middleware for the force action and the re-tare service",
        );
        d.any("model_update", "on_command (the force-control paper: the newest model is adopted at each force command) or continuous (each model on arrival, the standing command re-planned through it)");
    }

    /// The parameters of the models it starts with: the contact model, the surface, the arm's effects.
    fn declare_models(&self, d: &mut crate::runtime::params::Declarations) {
        let e = self.initial_model.exponents;
        let model = if [e.a, e.b, e.c].iter().all(|x| EXPONENT_RANGE.contains(x)) {
            self.initial_model.plausible().map_err(|e| e.to_string())
        } else {
            Err(format!("exponents outside {EXPONENT_RANGE:?}"))
        };
        d.rule(
            "initial_model",
            model,
            "a valid contact model",
            "the model used until the estimator has one (a rough guess is enough to start identification)",
        );
        let far = crate::contact_estimator::MAX_SURFACE_DISTANCE;
        let surface = match self.initial_surface {
            Some(p) if !(p.iter().all(|v| v.is_finite()) && Vector3::from(p).norm() <= far) => {
                Err(format!("{p:?} is not finite or farther than {far} m from the base"))
            }
            _ => Ok(()),
        };
        d.rule(
            "initial_surface",
            surface,
            "null, or a point [x, y, z] within 5 m of the base [m]",
            "where the undeformed surface lies in the world, if known before contact (`softcontact discrepancy FILE --out DIR` writes the workflow's placement into DIR/NAME.params.yaml): the first force command in contact places initial_model's surface there, refused beyond max_surface_offset from the onset [m]",
        );
        d.rule(
            "arm_effects",
            self.arm_effects.validate().map_err(|e| e.to_string()),
            "{joint_friction: {viscous: [7], coulomb: [7]}, payload: {mass, com: [3]}}, each optional and bounded",
            "the arm's own effects beyond the URDF to compensate, as `softcontact discrepancy --arm --out` writes them: joint friction fed forward, a flange payload carried in the dynamics",
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each law parameter is carried both ways: a configuration with every field off its default comes
    /// back whole through the node's parameters (a field one way forgets is caught).
    #[test]
    fn the_laws_configuration_comes_back_whole_through_the_nodes_parameters() {
        let mut c = ControllerConfig::lwr4(300.0, 0.07);
        c.normal = Vector3::new(0.0, 0.6, -0.8);
        c.gains = DeformationGains::critically_damped(33.0);
        c.lateral = (300.0, 30.0);
        c.orientation = (200.0, 20.0);
        c.posture_stiffness = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        c.posture_damping = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7];
        c.approach_speed = 0.02;
        c.max_approach = 0.2;
        c.onset = OnsetConfig { threshold: 2.0, confirm: 5 };
        c.limits.torque_rate = 1500.0;
        c.limits.max_lift = 0.03;
        c.limits.move_duration = (0.2, 100.0);
        c.limits.max_deformation_rate = 0.2;
        c.limits.contact_lost_below = 0.7;
        c.limits.force_limit = 350.0;
        c.max_surface_offset = 0.02;
        c.restart_after = 0.3;
        c.arm.payload = Some(softcontact_dynamics::Payload { mass: 0.5, com: [0.0, 0.0, 0.05] });
        let defaults = ControllerConfig::lwr4(250.0, 0.06);
        assert_ne!(c, defaults);
        assert_eq!(Params::from_law(&c).controller_config(), c);
        assert_eq!(Params::default().controller_config(), defaults);
    }
}
