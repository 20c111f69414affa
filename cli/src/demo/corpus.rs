//! The discrepancy workflow's hidden-effect corpus: recordings made by the lockstep cell (the simulated
//! arm, surface and F/T sensor with the real node structs, recorded as the demo records the graph), each
//! with an effect hidden in the simulator's surface or sensor, or none, and the workflow run on the file
//! as `softcontact discrepancy FILE` runs it. The workflow only reads the recording; the truth stays here.
//!
//! Every case runs the force-control paper's two excitations, shortened: identification (ramps and 1 Hz pushes) and
//! control (quintic moves to force commands, each followed by a hold); the sensor is tared at start-up and
//! before control, and the recording marks both tares.

use std::path::Path;

use serde::Serialize;
use softcontact_contact::{ContactModel, Effect, Exponents, Tangential};
use softcontact_sim::FtSensorConfig;

pub use super::case::{Case, ExpectedParameter};
use super::experiment::{Across, Plan, SurfaceSpec, run_hold, run_surface};
use super::record::Recorder;
use crate::discrepancy_cmd::{self, DiscrepancyArgs};
use crate::identify_cmd::IdentifyArgs;

/// What the workflow answered on one case.
#[derive(Debug, Clone, Serialize)]
pub struct Outcome {
    pub case: String,
    pub expected: Vec<String>,
    /// The expected answer when it is an ambiguity, "a or b".
    pub expected_ambiguous: Option<String>,
    pub named: Vec<String>,
    /// The ambiguities reported, "a or b" each.
    pub ambiguous: Vec<String>,
    pub remaining: String,
    pub visible_in: String,
    /// The gap the effect leaves in multiples of the noise σ: the refitted baseline's RMS over σ.
    pub size_sigma: f64,
    pub noise_floor: f64,
    pub rms_before: f64,
    pub rms_after: f64,
    /// Gap shrink over the ideal one, (1 − after/before) / (1 − σ/before); for effect cases.
    pub shrink_of_ideal: Option<f64>,
    /// The parameters checked, "name found (truth ± tolerance)" each, and whether all were within it.
    pub parameters: Vec<String>,
    pub parameters_within: bool,
    pub out_of_library: bool,
    /// The kind the law had to be re-chosen as (a case given a wrong kind), and the re-choice made
    /// ("from → to"), if any.
    pub expected_law: Option<String>,
    pub law_rechosen: Option<String>,
    pub exact: bool,
}

fn sponge_law() -> ContactModel {
    softcontact_sim::sponge()
}

fn dice_law() -> ContactModel {
    softcontact_sim::dice()
}

fn with(mut m: ContactModel, effects: &[Effect]) -> ContactModel {
    m.effects.extend_from_slice(effects);
    m
}

/// The law with a Walton tangential law and friction (the sway then loads the sensor sideways).
pub(super) fn gripping(mut m: ContactModel) -> ContactModel {
    m.tangential = Some(Tangential::walton(1.0e4, 0.8));
    m
}

fn noisy(scale: f64) -> FtSensorConfig {
    let mut s = FtSensorConfig::gamma();
    s.noise.iter_mut().for_each(|n| *n *= scale);
    s
}

/// A push plan's depth range \[m\] and largest force \[N\] on each of the force-control paper's laws.
pub(super) const SPONGE: ((f64, f64), f64) = ((0.01, 0.05), 300.0);
pub(super) const DICE: ((f64, f64), f64) = ((0.015, 0.07), 150.0);

/// The corpus: every effect of the cell's surface and sensor alone on both the force-control paper's laws, two-effect cases,
/// the demo's lab surfaces, an effect outside the library, and 40 nulls (two laws each: four noise levels,
/// three seeds; with sway and tilt, two seeds; coloured noise, a slowly wandering offset and a sensor
/// drifting slower than the tares follow, `slow_noise_seeds` seeds each, two in the committed table).
/// Each case's seed follows from its place in the list: new cases go last.
pub fn cases(slow_noise_seeds: usize) -> Vec<Case> {
    let mut corpus = Corpus { out: vec![], seed: 100 };
    for (law, base, geometry, k_m) in [("sponge", sponge_law(), SPONGE, 1500.0), ("dice", dice_law(), DICE, 300.0)] {
        corpus.effects_of_the_surface(law, &base, geometry, k_m);
        corpus.effects_of_the_sensor_and_hand(law, &base, geometry, k_m);
    }
    corpus.lab_surfaces_and_out_of_library();
    corpus.one_long_hold();
    corpus.nulls(slow_noise_seeds);
    corpus.effects_added_later();
    let mut out = corpus.out;
    for c in out.iter_mut() {
        if c.visible_in == ONE_HOLD {
            c.hold = Some(40.0);
            c.ambiguous = Some(["contact_offset_drift", "sensor_drift"]);
        }
        if c.visible_in == WANDERING {
            c.may_name = Some("sensor_drift");
        }
    }
    out
}

/// The cases in order, each with the next seed.
struct Corpus {
    out: Vec<Case>,
    seed: u64,
}

impl Corpus {
    fn case(
        &mut self,
        name: String,
        truth: ContactModel,
        sensor: FtSensorConfig,
        (push, max_force): ((f64, f64), f64),
        expected: Vec<&'static str>,
        visible_in: &'static str,
    ) {
        self.seed += 1;
        let across =
            if visible_in.contains("sway") || visible_in.contains("tilt") { Across::AlongX } else { Across::No };
        let out_of_library = visible_in.contains("out of library");
        // A tare taken touching: the hand starts pressed 2 mm (dice: 1 mm) and is never tared again.
        let start_pressed =
            visible_in.contains("tare taken touching").then_some(if max_force > 200.0 { 0.002 } else { 0.001 });
        let case = Case::new(name, truth, sensor, (push, max_force), expected, self.seed);
        self.out.push(Case { visible_in, across, out_of_library, start_pressed, ..case });
    }

    /// The surface's own effects on `base`, one at a time, then relaxation with hysteresis.
    fn effects_of_the_surface(&mut self, law: &str, base: &ContactModel, geometry: ((f64, f64), f64), k_m: f64) {
        let g = FtSensorConfig::gamma;
        self.case(
            format!("{law}: relaxation k_m {k_m} N/m, τ 1 s"),
            with(base.clone(), &[Effect::ViscoelasticRelaxation { stiffness: k_m, time_constant: 1.0 }]),
            g(),
            geometry,
            vec!["viscoelastic_relaxation"],
            "holds after moves",
        );
        self.case(
            format!("{law}: hysteresis 3 % at 5 cm/s"),
            with(base.clone(), &[Effect::Hysteresis { fraction: 0.03, velocity_scale: 0.05 }]),
            g(),
            geometry,
            vec!["hysteresis"],
            "loading against unloading (pushes)",
        );
        self.case(
            format!("{law}: surface zero creeping 5 µm/s"),
            with(base.clone(), &[Effect::ContactOffsetDrift { rate: 5e-6 }]),
            g(),
            geometry,
            vec!["contact_offset_drift"],
            "repeated pushes minutes apart",
        );
        // Five times the demo's warming Gamma: over the ~20 s between this plan's tares its drift reaches
        // ~0.4 N (8 σ); the demo's own rate stays within 1.5 σ here (see the lab cases).
        let mut drifting = FtSensorConfig::gamma_drifting();
        drifting.drift.iter_mut().for_each(|d| *d *= 5.0);
        self.case(
            format!("{law}: sensor drifting 0.02 N/s"),
            base.clone(),
            drifting,
            geometry,
            vec!["sensor_drift"],
            "free space between runs, tares",
        );
        // Damping λ·ż as Kelvin-Voigt's, so that only the elastic exponent differs from a kind.
        let (k, a, damping) = if law == "sponge" {
            (280.0 / 0.05f64.powf(1.2), 1.2, 200.0)
        } else {
            (130.0 / 0.07f64.powf(1.25), 1.25, 60.0)
        };
        self.case(
            format!("{law}: force ∝ z^{a}"),
            ContactModel::general(k, damping, Exponents { a, b: 0.0, c: 1.0 }).expect("valid law"),
            g(),
            geometry,
            vec!["stiffness_exponent"],
            "pushes to several depths",
        );
    }

    /// The sensor's and the hand's effects, the delay, and two surface effects together.
    fn effects_of_the_sensor_and_hand(
        &mut self,
        law: &str,
        base: &ContactModel,
        geometry: ((f64, f64), f64),
        k_m: f64,
    ) {
        let g = FtSensorConfig::gamma;
        // The snake paper's named error: the sensor axis misaligned 1° with the pushing axis (about y), which
        // reads the tangential load along x into the normal channel (coupling n × ω).
        let misaligned = 1f64.to_radians();
        self.case(
            format!("{law}: sensor axis misaligned 1° (the snake paper)"),
            with(gripping(base.clone()), &[Effect::SensorCrosstalk { coupling: [misaligned, 0.0, 0.0] }]),
            g(),
            geometry,
            vec!["sensor_crosstalk"],
            "lateral sway at a held force",
        );
        self.case(
            format!("{law}: hand 0.6 kg heavier than its URDF"),
            with(gripping(base.clone()), &[Effect::ToolGravity { mass: 0.6 }]),
            g(),
            geometry,
            vec!["tool_gravity"],
            "tilts of the hand in free space",
        );
        self.case(
            format!("{law}: tare taken touching the surface"),
            base.clone(),
            g(),
            geometry,
            vec!["sensor_bias"],
            "free space (a tare taken touching)",
        );
        self.case(
            format!("{law}: force read 30 ms late"),
            with(base.clone(), &[Effect::TimeDelay { delay: 0.03 }]),
            g(),
            geometry,
            vec!["time_delay"],
            "stops and lift-offs",
        );
        self.case(
            format!("{law}: relaxation and hysteresis"),
            with(
                base.clone(),
                &[
                    Effect::ViscoelasticRelaxation { stiffness: k_m, time_constant: 1.0 },
                    Effect::Hysteresis { fraction: 0.03, velocity_scale: 0.05 },
                ],
            ),
            g(),
            geometry,
            vec!["hysteresis", "viscoelastic_relaxation"],
            "holds; loading against unloading",
        );
    }

    fn lab_surfaces_and_out_of_library(&mut self) {
        // The demo's surfaces: expected, what they hide. The demo's sensor drifts 0.004 N/s, under 1 σ
        // between this short plan's tares (a sawtooth to 0.08 N): here a Gamma that does not drift, and the
        // drift is named on the demo's own recordings (80 s between tares; cli/tests/demo.rs).
        self.case(
            "lab sponge (the demo's surface)".into(),
            softcontact_sim::lab_sponge(),
            FtSensorConfig::gamma(),
            SPONGE,
            vec!["hysteresis", "viscoelastic_relaxation"],
            "holds, pushes",
        );
        self.case(
            "lab dice (the demo's surface)".into(),
            softcontact_sim::lab_dice(),
            FtSensorConfig::gamma(),
            DICE,
            vec!["hysteresis", "viscoelastic_relaxation"],
            "holds, pushes",
        );
        // Out of the library: the rate term grows with ż² (the baseline kinds and the effects have it linear).
        let mut quadratic = sponge_law();
        quadratic.kind = softcontact_contact::Kind::General;
        quadratic.exponents = Exponents { a: 1.5, b: 0.5, c: 2.0 };
        quadratic.damping = 22_000.0;
        self.case(
            "sponge: damping ∝ ż² (out of library)".into(),
            quadratic,
            FtSensorConfig::gamma(),
            SPONGE,
            vec![],
            "pushes at speed (out of library)",
        );
    }

    fn one_long_hold(&mut self) {
        // One long hold with no lift-off after it: a drifting sensor and a creeping surface both read as force
        // growing linearly in time there, so the answer is "ambiguous", not a guess (the free approach before
        // the hold is too short to tell them apart).
        let mut drifting = FtSensorConfig::gamma_drifting();
        drifting.drift.iter_mut().for_each(|d| *d *= 2.5);
        for (name, law, sensor, geometry) in [
            ("dice: sensor drifting 0.01 N/s through one 40 s hold", dice_law(), drifting, DICE),
            (
                "sponge: surface zero creeping 5 µm/s through one 40 s hold",
                with(sponge_law(), &[Effect::ContactOffsetDrift { rate: 5e-6 }]),
                FtSensorConfig::gamma(),
                SPONGE,
            ),
        ] {
            let hidden = if law.effects.is_empty() { "sensor_drift" } else { "contact_offset_drift" };
            self.case(name.into(), law, sensor, geometry, vec![hidden], ONE_HOLD);
        }
    }

    /// Nothing hidden: white noise at four levels, sway and tilt, coloured noise, a wandering offset and
    /// a drift the tares follow.
    fn nulls(&mut self, slow_noise_seeds: usize) {
        for (law, base, geometry) in [("sponge", sponge_law(), SPONGE), ("dice", dice_law(), DICE)] {
            for seed in 0..2 {
                let name = format!("null: {law} with sway and tilt ({})", seed + 1);
                self.case(name, gripping(base.clone()), FtSensorConfig::gamma(), geometry, vec![], "- (sway, tilt)");
            }
            for scale in [0.5, 1.0, 2.0, 4.0] {
                for _ in 0..3 {
                    self.case(
                        format!("null: {law}, noise ×{scale}"),
                        base.clone(),
                        noisy(scale),
                        geometry,
                        vec![],
                        "-",
                    );
                }
            }
            // Noise that is not white, as large as the white noise: low-passed (50 ms), and a slow wander of
            // the offset (20 s, which within a record may look like a steady drift of the reading, the only
            // name it may get: see `may_name`). And a steady drift slow enough that between the plan's tares
            // (about 20 s) it stays within the noise: the tares follow it.
            let coloured = |time_constant| FtSensorConfig {
                coloured_noise: FtSensorConfig::gamma().noise,
                coloured_time_constant: time_constant,
                ..FtSensorConfig::gamma()
            };
            let mut slow_drift = FtSensorConfig::gamma_drifting();
            slow_drift.drift.iter_mut().for_each(|d| *d *= 0.25);
            for (what, sensor, visible_in) in [
                ("coloured noise (50 ms)", coloured(0.05), COLOURED),
                ("offset wandering (20 s)", coloured(20.0), WANDERING),
                ("sensor drifting 0.001 N/s", slow_drift, "- (a drift the tares follow)"),
            ] {
                for _ in 0..slow_noise_seeds {
                    self.case(
                        format!("null: {law}, {what}"),
                        base.clone(),
                        sensor.clone(),
                        geometry,
                        vec![],
                        visible_in,
                    );
                }
            }
        }
    }

    fn effects_added_later(&mut self) {
        // Effects added to the library later, last: the cases before them keep their seeds.
        for (law, base, geometry) in [("sponge", sponge_law(), SPONGE), ("dice", dice_law(), DICE)] {
            self.case(
                format!("{law}: adhesion pulling 10 % of the peak force, letting go 2 mm beyond the surface"),
                with(base.clone(), &[Effect::Adhesion { force: 0.1 * geometry.1, range: 0.002 }]),
                FtSensorConfig::gamma(),
                geometry,
                vec!["adhesion"],
                "unloading and lift-off (pushes)",
            );
            // On the dice's linear law Fung's form is a Maxwell branch of g·k exactly (`Effect::
            // QuasiLinearRelaxation`): no recording tells them apart, and the answer is the default form.
            let form = if law == "dice" { "viscoelastic_relaxation" } else { "quasi_linear_relaxation" };
            self.case(
                format!("{law}: quasi-linear relaxation, 15 % of the elastic force, τ 1 s"),
                with(base.clone(), &[Effect::QuasiLinearRelaxation { fraction: 0.15, time_constant: 1.0 }]),
                FtSensorConfig::gamma(),
                geometry,
                vec![form],
                "holds after moves to several depths",
            );
        }
    }
}

const ONE_HOLD: &str = "one long hold (no lift-off after it)";

const COLOURED: &str = "- (coloured noise)";
const WANDERING: &str = "- (a wandering offset; may read as sensor drift)";

/// The plan of every case: three identification runs and one cycle of six force commands.
const PLAN: Plan = Plan {
    identification_runs: 3,
    push_periods: 5,
    commands: 6,
    move_duration: 2.0,
    across: Across::No,
    start_pressed: None,
    augmented: false,
};

/// `softcontact discrepancy FILE --out DIR --sample-period P` with the cell's normal (down).
fn args(file: &Path, out: &Path, sample_period: f64) -> DiscrepancyArgs {
    DiscrepancyArgs {
        recording: IdentifyArgs {
            file: file.to_path_buf(),
            json: None,
            normal: vec![0.0, 0.0, -1.0],
            onset: None,
            sample_period: Some(sample_period),
        },
        model: None,
        surface: None,
        out: out.to_path_buf(),
        loading_paths: false,
        arm: false,
        closed_loop: false,
    }
}

/// Records one case into `dir` and runs the workflow on the file.
pub fn run_case(case: &Case, dir: &Path, keep: bool) -> anyhow::Result<Outcome> {
    let spec = SurfaceSpec {
        name: "corpus",
        truth: case.truth.clone(),
        push: case.push,
        push_forces: (0.0, 0.0),
        max_force: case.max_force,
        max_deformation: 0.08,
        sensor: case.sensor.clone(),
        foreign: case.foreign.clone(),
    };
    let path = dir.join(format!("case{}.mcap", case.seed));
    let mut recorder = Recorder::create(&path, 1_700_000_000_000_000_000)?;
    let mut args = args(&path, dir, 0.01);
    if let Some(kind) = case.given_kind {
        let model = dir.join(format!("case{}.model.yaml", case.seed));
        std::fs::write(&model, super::case::in_kind(&case.truth, kind, 0.5 * (case.push.0 + case.push.1)).to_yaml())?;
        args.model = Some(model);
    }
    if let Some(hold) = case.hold {
        // The surface as identified before: its law without the hidden effects.
        let mut known = case.truth.clone();
        known.effects.clear();
        run_hold(&spec, &known, 0.5 * case.max_force, hold, case.seed, &mut recorder)?;
        let model = dir.join(format!("case{}.model.yaml", case.seed));
        std::fs::write(&model, known.to_yaml())?;
        args.model = Some(model);
    } else {
        let plan = Plan { across: case.across, start_pressed: case.start_pressed, ..PLAN };
        run_surface(&spec, plan, case.seed, &mut recorder)?;
    }
    recorder.finish()?;
    let a = discrepancy_cmd::analyse_file(&args, false)?;
    if !keep {
        std::fs::remove_file(&path)?;
        if let Some(model) = &args.model {
            std::fs::remove_file(model)?;
        }
    }
    let r = &a.report;
    let mut named: Vec<String> = r.effects.iter().map(|e| e.id.clone()).collect();
    named.sort();
    named.dedup();
    let expected: Vec<String> = case.expected.iter().map(|s| s.to_string()).collect();
    let before = r.refit.rms;
    let ideal = 1.0 - r.noise_floor / before;
    let remaining = format!("{:?}", r.remaining).to_lowercase();
    let pair = |p: &[String; 2]| {
        let mut p = p.clone();
        p.sort();
        p.join(" or ")
    };
    let ambiguous: Vec<String> = r.ambiguous.iter().map(|a| pair(&a.between)).collect();
    let expected_ambiguous = case.ambiguous.map(|p| pair(&p.map(String::from)));
    let shrink_of_ideal = (!case.expected.is_empty() && case.ambiguous.is_none() && ideal > 0.0)
        .then(|| (1.0 - r.final_rms / before) / ideal);
    let (parameters, parameters_within) = check_parameters(r, &case.parameters);
    let law_rechosen = r.law_rechosen.as_ref().map(|c| format!("{} → {}", c.from.id(), c.to.id()));
    let expected_law = case.given_kind.map(|_| case.truth.kind.id().to_string());
    let law_as_expected = expected_law.as_ref().is_none_or(|k| r.refit.kind.id() == k);
    let exact = parameters_within
        && law_as_expected
        && (case.expected.is_empty()
            || case.min_shrink_of_ideal <= 0.0
            || shrink_of_ideal.is_some_and(|x| x >= case.min_shrink_of_ideal))
        && match &expected_ambiguous {
            Some(p) => named.is_empty() && remaining == "ambiguous" && ambiguous.contains(p),
            None if case.expected.is_empty() => named.iter().all(|n| case.may_name == Some(n.as_str())),
            None => named == expected && (!case.out_of_library || remaining == "unexplained"),
        };
    Ok(Outcome {
        case: case.name.clone(),
        exact,
        out_of_library: case.out_of_library,
        expected,
        expected_ambiguous,
        named,
        ambiguous,
        remaining,
        visible_in: case.visible_in.into(),
        size_sigma: before / r.noise_floor,
        noise_floor: r.noise_floor,
        rms_before: before,
        rms_after: r.final_rms,
        shrink_of_ideal,
        parameters,
        parameters_within,
        expected_law,
        law_rechosen,
    })
}

/// Each expected parameter as found against its truth, and whether every one is within its tolerance (a
/// parameter of an effect not named is not within it).
fn check_parameters(r: &softcontact_discrepancy::Report, expected: &[ExpectedParameter]) -> (Vec<String>, bool) {
    let mut within = true;
    let shown = expected
        .iter()
        .map(|p| {
            let effect = r.effects.iter().find(|e| e.id == p.id);
            let found: Vec<f64> = p
                .names
                .iter()
                .map(|n| effect.and_then(|e| e.parameters.get(*n)).copied().unwrap_or(f64::NAN))
                .collect();
            let distance = found.iter().zip(&p.truth).map(|(f, t)| (f - t).powi(2)).sum::<f64>().sqrt();
            within &= distance <= p.tolerance;
            let (unit, size) = p.unit;
            let list = |v: &[f64]| v.iter().map(|x| format!("{:.3}", x / size)).collect::<Vec<_>>().join(", ");
            format!("{} {} {unit} ({} ± {:.2})", p.names.join("/"), list(&found), list(&p.truth), p.tolerance / size)
        })
        .collect();
    (shown, within)
}

/// The goals of the corpus (issue 16): ≥ 90 % of effect cases named exactly, no false name on a null,
/// median gap shrink ≥ 80 % of the ideal.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub effect_cases: usize,
    pub named_exactly: usize,
    pub null_cases: usize,
    pub false_names_on_nulls: usize,
    /// Out-of-library cases, and those answered with no name and `unexplained`.
    pub out_of_library_cases: usize,
    pub out_of_library_unexplained: usize,
    /// Cases whose answer is an ambiguity, and those answered with it (counted in the effect cases too).
    pub ambiguous_cases: usize,
    pub ambiguous_answered: usize,
    pub median_shrink_of_ideal: f64,
    pub outcomes: Vec<Outcome>,
}

/// Runs `cases` on `threads` threads (each case is an independent cell): every one, or those whose name
/// contains `only`; with `keep`, each case's recording stays in that folder.
pub fn run(cases: Vec<Case>, threads: usize, only: Option<&str>, keep: Option<&Path>) -> anyhow::Result<Summary> {
    let dir = match keep {
        Some(dir) => {
            std::fs::create_dir_all(dir)?;
            dir.to_path_buf()
        }
        None => tempfile_dir()?,
    };
    let cases: Vec<Case> = cases.into_iter().filter(|c| only.is_none_or(|o| c.name.contains(o))).collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut outcomes: Vec<(usize, Outcome)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads.max(1))
            .map(|_| {
                scope.spawn(|| -> anyhow::Result<Vec<(usize, Outcome)>> {
                    let mut mine = vec![];
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(case) = cases.get(i) else { return Ok(mine) };
                        let outcome = run_case(case, &dir, keep.is_some())
                            .map_err(|e| anyhow::anyhow!("{}: {e:#}", case.name))?;
                        mine.push((i, outcome));
                    }
                })
            })
            .collect();
        workers.into_iter().map(|w| w.join().expect("corpus worker")).collect::<anyhow::Result<Vec<_>>>()
    })?
    .into_iter()
    .flatten()
    .collect();
    if keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    outcomes.sort_by_key(|(i, _)| *i);
    let outcomes: Vec<Outcome> = outcomes.into_iter().map(|(_, o)| o).collect();
    let effects: Vec<&Outcome> = outcomes.iter().filter(|o| !o.expected.is_empty()).collect();
    let null = |o: &&Outcome| o.expected.is_empty() && !o.out_of_library;
    let nulls: Vec<&Outcome> = outcomes.iter().filter(null).collect();
    let outside: Vec<&Outcome> = outcomes.iter().filter(|o| o.out_of_library).collect();
    let mut shrink: Vec<f64> = effects.iter().filter_map(|o| o.shrink_of_ideal).collect();
    shrink.sort_by(f64::total_cmp);
    Ok(Summary {
        effect_cases: effects.len(),
        named_exactly: effects.iter().filter(|o| o.exact).count(),
        null_cases: nulls.len(),
        false_names_on_nulls: nulls.iter().filter(|o| !o.exact).count(),
        out_of_library_cases: outside.len(),
        out_of_library_unexplained: outside.iter().filter(|o| o.exact).count(),
        ambiguous_cases: outcomes.iter().filter(|o| o.expected_ambiguous.is_some()).count(),
        ambiguous_answered: outcomes.iter().filter(|o| o.expected_ambiguous.is_some() && o.exact).count(),
        median_shrink_of_ideal: shrink.get(shrink.len() / 2).copied().unwrap_or(f64::NAN),
        outcomes,
    })
}

fn tempfile_dir() -> anyhow::Result<std::path::PathBuf> {
    let dir = std::env::temp_dir().join(format!("softcontact-corpus-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

/// The table printed by `softcontact bench discrepancy` (and committed in docs/discrepancy-corpus.md).
pub fn table(s: &Summary) -> String {
    let with_parameters = s.outcomes.iter().any(|o| !o.parameters.is_empty());
    let mut t = String::from(
        "| case | hidden | expected answer | named | remaining | visible in | gap/σ | σ [N] | RMS before → after [N] | shrink/ideal |",
    );
    t += if with_parameters { " parameters found (truth ± tolerance) |\n" } else { "\n" };
    t += "|---|---|---|---|---|---|---|---|---|---|";
    t += if with_parameters { "---|\n" } else { "\n" };
    for o in &s.outcomes {
        let list = |v: &[String]| if v.is_empty() { "—".to_string() } else { v.join(", ") };
        let mut answer = match &o.expected_ambiguous {
            Some(p) => format!("ambiguous: {p}"),
            None if o.out_of_library => "unexplained".into(),
            None => list(&o.expected),
        };
        let mut named = if o.ambiguous.is_empty() {
            list(&o.named)
        } else {
            format!("{} (ambiguous: {})", list(&o.named), o.ambiguous.join("; "))
        };
        if let Some(kind) = &o.expected_law {
            answer += &format!("; the law re-chosen as {kind}");
        }
        if let Some(choice) = &o.law_rechosen {
            named += &format!("; the law re-chosen: {choice}");
        }
        t += &format!(
            "| {}{} | {} | {} | {} | {} | {} | {:.1} | {:.3} | {:.3} → {:.3} | {} |\n",
            o.case,
            if o.exact { "" } else { " ✗" },
            list(&o.expected),
            answer,
            named,
            o.remaining,
            o.visible_in,
            o.size_sigma,
            o.noise_floor,
            o.rms_before,
            o.rms_after,
            o.shrink_of_ideal.map_or("—".into(), |x| format!("{:.0} %", 100.0 * x)),
        );
        if with_parameters {
            t.pop();
            let shown = if o.parameters.is_empty() { "—".to_string() } else { o.parameters.join("; ") };
            t += &format!(" {shown} |\n");
        }
    }
    t += &format!(
        "\nEffect cases named exactly: {}/{} ({:.0} %; of them answered ambiguous as expected: {}/{}); false names on nulls: {}/{}; out of library left unexplained: {}/{}; median shrink of the ideal: {:.0} %\n",
        s.named_exactly,
        s.effect_cases,
        100.0 * s.named_exactly as f64 / s.effect_cases.max(1) as f64,
        s.ambiguous_answered,
        s.ambiguous_cases,
        s.false_names_on_nulls,
        s.null_cases,
        s.out_of_library_unexplained,
        s.out_of_library_cases,
        100.0 * s.median_shrink_of_ideal,
    );
    t
}

/// The whole workflow (read, pair, identify, analyse) on the demo's lab sponge recorded by the corpus
/// plan and analysed at 1 kHz, best of three on this thread: (recorded seconds, samples, seconds).
pub fn time_workflow() -> anyhow::Result<(f64, usize, f64)> {
    let dir = tempfile_dir()?;
    let path = dir.join("timing.mcap");
    let [spec, _] = super::surfaces();
    let mut recorder = Recorder::create(&path, 1_700_000_000_000_000_000)?;
    let run = run_surface(&spec, PLAN, 7, &mut recorder)?;
    recorder.finish()?;
    let args = args(&path, &dir, 0.001);
    let mut best = f64::INFINITY;
    let mut samples = 0;
    for _ in 0..3 {
        let started = std::time::Instant::now();
        let a = discrepancy_cmd::analyse_file(&args, false)?;
        best = best.min(started.elapsed().as_secs_f64());
        samples = a.series.len();
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok((run.simulated, samples, best))
}

/// What `softcontact bench discrepancy` runs.
pub struct Corpora {
    /// Only the workflow's time.
    pub timing_only: bool,
    /// Only the foreign-effect corpus.
    pub foreign_only: bool,
    /// Seeds of each null whose noise is not white.
    pub slow_noise_seeds: usize,
}

/// `softcontact bench discrepancy`: the workflow's time, today's corpus and the foreign-effect corpus.
pub fn bench(
    threads: usize,
    json: Option<std::path::PathBuf>,
    corpora: Corpora,
    only: Option<&str>,
    keep: Option<&Path>,
) -> anyhow::Result<()> {
    let Corpora { timing_only, foreign_only, slow_noise_seeds } = corpora;
    let mut value = serde_json::json!({});
    if only.is_none() && !foreign_only {
        let (seconds, samples, wall) = time_workflow()?;
        println!(
            "workflow on a {seconds:.0} s recording at 1 kHz ({samples} samples): {wall:.2} s (the delay screened on a second core where there is one; {:.2} s per 60 s; goal < 2 s)",
            wall * 60.0 / seconds
        );
        value["timing"] = serde_json::json!({
            "recorded_s": seconds, "samples": samples, "wall_s": wall, "wall_per_60s": wall * 60.0 / seconds
        });
    }
    if !timing_only {
        let mut corpora = vec![("foreign-effect corpus", "foreign_corpus", super::foreign_corpus::cases())];
        if !foreign_only {
            corpora.insert(0, ("hidden-effect corpus", "corpus", cases(slow_noise_seeds)));
        }
        for (what, key, cases) in corpora {
            let started = std::time::Instant::now();
            let summary = run(cases, threads, only, keep)?;
            println!("\n{what} ({:.1} s wall):\n{}", started.elapsed().as_secs_f64(), table(&summary));
            value[key] = serde_json::to_value(&summary)?;
        }
    }
    if let Some(path) = json {
        crate::identify_cmd::write_json(&path, &value)?;
    }
    Ok(())
}
