//! A case of the discrepancy corpora: one recording to make (the truth the simulator hides, the sensor,
//! the excitation) and what the workflow should answer on it.

use softcontact_contact::{ContactModel, Kind};
use softcontact_sim::FtSensorConfig;
use softcontact_sim::foreign::ForeignEffect;

use super::experiment::Across;

/// One recording to make and what the workflow should answer.
pub struct Case {
    pub name: String,
    pub truth: ContactModel,
    pub sensor: FtSensorConfig,
    /// The base law's push range \[m\] and the controller's force limit \[N\].
    pub push: (f64, f64),
    pub max_force: f64,
    /// The effect ids the workflow should name (empty: a null case).
    pub expected: Vec<&'static str>,
    /// The excitation that shows the effect.
    pub visible_in: &'static str,
    /// The plan's lateral sway and tilts ([`super::experiment::Plan::across`]).
    pub across: Across,
    /// An effect outside the library: the answer must be no name and `unexplained`.
    pub out_of_library: bool,
    /// [`super::experiment::Plan::start_pressed`].
    pub start_pressed: Option<f64>,
    /// Instead of the plan, one long hold of this many seconds on a surface identified earlier (the law
    /// without its effects, given with `--model`): see [`super::experiment::run_hold`].
    pub hold: Option<f64>,
    /// The answer is no name and "ambiguous between these two" (the recording cannot separate them).
    pub ambiguous: Option<[&'static str; 2]>,
    /// A null whose recording really shows this effect of the sensor, though no effect was hidden: naming
    /// it is no false name (an offset that wanders as far as a steady drift would within the record).
    pub may_name: Option<&'static str>,
    /// Surface effects outside the library, added to `truth`'s force (the foreign cases).
    pub foreign: Vec<ForeignEffect>,
    /// The baseline given with `--model` instead of identify's: `truth`'s law, without its effects, in this
    /// wrong kind. The answer must re-choose `truth`'s kind.
    pub given_kind: Option<Kind>,
    /// Parameters the answer must carry within their tolerance.
    pub parameters: Vec<ExpectedParameter>,
    /// The least shrink of the gap, over the ideal one, of an answer as expected (0: the names alone).
    pub min_shrink_of_ideal: f64,
    pub seed: u64,
}

impl Case {
    /// A case seeded `seed` with no excitation named, no sway, tilt, hold or parameter checked: each
    /// corpus sets what differs.
    pub fn new(
        name: String,
        truth: ContactModel,
        sensor: FtSensorConfig,
        (push, max_force): ((f64, f64), f64),
        expected: Vec<&'static str>,
        seed: u64,
    ) -> Self {
        Case {
            name,
            truth,
            sensor,
            push,
            max_force,
            expected,
            visible_in: "",
            across: Across::No,
            out_of_library: false,
            start_pressed: None,
            hold: None,
            ambiguous: None,
            may_name: None,
            foreign: vec![],
            given_kind: None,
            parameters: vec![],
            min_shrink_of_ideal: 0.0,
            seed,
        }
    }
}

/// A parameter of a named effect the answer must carry: the effect's `id`, its parameter `name`s (one, or
/// the components of a vector, compared by the distance between vectors), the truth and the tolerance.
#[derive(Debug, Clone)]
pub struct ExpectedParameter {
    pub id: &'static str,
    pub names: Vec<&'static str>,
    pub truth: Vec<f64>,
    pub tolerance: f64,
    /// How the table shows it: the unit's name and its size in the parameter's unit (ms: 1e-3).
    pub unit: (&'static str, f64),
}

/// `law` without its effects in `kind`'s exponents, its stiffness and damping scaled to give the same
/// force at `depth` (at any one speed): a plausible wrong choice, as a fit of that kind would find.
pub fn in_kind(law: &ContactModel, kind: Kind, depth: f64) -> ContactModel {
    let exponents = kind.exponents().expect("a named kind");
    let mut out = ContactModel { kind, exponents, effects: vec![], ..law.clone() };
    out.stiffness = law.stiffness * depth.powf(law.exponents.a - exponents.a);
    out.damping = law.damping * depth.powf(law.exponents.b - exponents.b);
    out
}
