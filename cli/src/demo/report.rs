//! The demo's tables: the force-control paper's Table I (fitness) and Tables II/III (errors per command and cycle),
//! ours beside the paper's, and the same as JSON.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use softcontact_contact::{ContactModel, Effect, Exponents};

use super::experiment::{CYCLES, CommandResult, ModelUse, RATIOS, SurfaceRun};
use super::paper::{self, PaperSurface};

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    /// Always true: these are simulated surfaces, not the paper's robot.
    pub simulation: bool,
    /// `in-process` (lockstep) or `graph` (node processes over DDS).
    pub mode: String,
    pub surfaces: Vec<SurfaceReport>,
    /// The arm's own effects named and compensated (in-process runs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arm: Option<super::arm::ArmReport>,
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Fitness {
    pub mean: f64,
    pub std: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Identified {
    pub kind: String,
    pub stiffness: f64,
    pub damping: f64,
    pub exponents: Exponents,
    pub contact_position: [f64; 3],
    pub samples: usize,
}

/// One surface: the JSON of the demo's contract in docs/contracts.md, and what the tables print.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SurfaceReport {
    pub name: String,
    /// Cross-validated fitness of every kind, by kind id.
    pub fitness: BTreeMap<String, Fitness>,
    pub selected: String,
    pub identified: Identified,
    /// The largest normal force of the identification \[N\]: commands are ratios of it.
    pub max_force: f64,
    /// Both control experiments' commands: `model` is `identified` or `augmented`.
    pub commands: Vec<CommandResult>,
    pub simulated_surface: ContactModel,
    /// What the discrepancy workflow named in the identification runs (absent when it was not run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrepancy: Option<Discrepancy>,
}

/// The discrepancy workflow on the identification runs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Discrepancy {
    /// The effects named, with their parameters (SI units), in the order they were added.
    pub named: Vec<NamedEffect>,
    /// `none`, `unexplained` or `ambiguous`: what is left after them.
    pub remaining: String,
    /// In-contact RMS of the identified model and of the augmented one \[N\], and the noise floor.
    pub rms_before: f64,
    pub rms_after: f64,
    pub noise_floor: f64,
    /// The model cycle 1 of the second control experiment went through.
    pub augmented_model: ContactModel,
}

impl Discrepancy {
    pub fn of(r: &softcontact_discrepancy::Report) -> Self {
        Self {
            named: r
                .effects
                .iter()
                .map(|e| NamedEffect { id: e.id.clone(), parameters: e.parameters.clone() })
                .collect(),
            remaining: serde_json::to_value(r.remaining)
                .ok()
                .and_then(|v| v.as_str().map(String::from))
                .unwrap_or_default(),
            rms_before: r.refit.rms,
            rms_after: r.final_rms,
            noise_floor: r.noise_floor,
            augmented_model: r.model.clone(),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NamedEffect {
    pub id: String,
    pub parameters: BTreeMap<String, f64>,
}

impl SurfaceReport {
    pub fn of(run: &SurfaceRun) -> Self {
        let m = &run.identified.model;
        let p = run.identified.contact_position;
        Self {
            name: run.spec.name.into(),
            fitness: run
                .fits()
                .iter()
                .map(|f| (f.kind.id().into(), Fitness { mean: f.fitness_mean, std: f.fitness_std }))
                .collect(),
            selected: run.selected().id().into(),
            identified: Identified {
                kind: m.kind.id().into(),
                stiffness: m.stiffness,
                damping: m.damping,
                exponents: m.exponents,
                contact_position: [p.x, p.y, p.z],
                samples: run.identification_samples,
            },
            max_force: run.max_force,
            commands: run.commands.clone(),
            simulated_surface: run.spec.truth.clone(),
            discrepancy: run.augmented.as_ref().map(|(found, _)| Discrepancy::of(&found.report)),
        }
    }

    fn paper(&self) -> &'static PaperSurface {
        if self.name == "dice" { &paper::DICE } else { &paper::SPONGE }
    }

    /// The largest relative error of each cycle of the control experiment through `model`.
    pub fn worst_per_cycle(&self, model: ModelUse) -> Vec<f64> {
        (1..=CYCLES)
            .map(|c| {
                self.commands
                    .iter()
                    .filter(|x| x.cycle == c && x.model == model)
                    .map(|x| x.error / x.command)
                    .fold(f64::NAN, f64::max)
            })
            .collect()
    }
}

/// The effects a simulated surface carries beyond its law, in words.
pub fn describe(model: &ContactModel) -> String {
    let mut parts = vec![format!("{} law, k {:.0}, λ {:.0}", model.kind.id(), model.stiffness, model.damping)];
    for e in &model.effects {
        parts.push(match *e {
            Effect::ViscoelasticRelaxation { stiffness, time_constant } => {
                format!("viscoelastic relaxation ({stiffness:.0} N/m, τ {time_constant:.3} s)")
            }
            Effect::Hysteresis { fraction, velocity_scale } => {
                format!("hysteresis (±{:.1} % of the elastic force at {velocity_scale:.3} m/s)", fraction * 100.0)
            }
            Effect::SensorBias { offset } => format!("sensor bias ({offset:+.3} N)"),
            Effect::SensorDrift { rate } => format!("sensor drift ({:+.2} mN/s)", rate * 1e3),
            Effect::QuasiLinearRelaxation { fraction, time_constant } => {
                format!(
                    "quasi-linear relaxation ({:.0} % of the elastic force, τ {time_constant:.3} s)",
                    fraction * 100.0
                )
            }
            Effect::Adhesion { force, range } => {
                format!("adhesion (pull-off {force:.2} N, letting go {:.1} mm beyond the surface)", range * 1e3)
            }
            Effect::MediumDrag { damping, .. } => format!("medium drag ({damping:.2} N·s/m)"),
            ref other => other.id().to_string(),
        });
    }
    parts.join(" + ")
}

const KINDS: [(&str, &str); 3] =
    [("kelvin_voigt", "linear K/V"), ("hunt_crossley", "non-linear H/C"), ("azad_featherstone", "non-linear A/F")];

fn short(id: &str) -> &str {
    KINDS.iter().find(|(k, _)| *k == id).map_or(id, |(_, s)| s)
}

pub fn print_table_one(surfaces: &[SurfaceReport], source: &str) {
    println!("TABLE I — fitness (eq. 18) of three contact models, 5-fold cross-validated, mean ± std");
    print!("{:<8} {:<7}", "", "");
    for (_, name) in KINDS {
        print!(" {name:>16}");
    }
    println!("   chosen");
    for s in surfaces {
        print!("{:<8} {:<7}", s.name, "ours");
        for (k, _) in KINDS {
            match s.fitness.get(k) {
                Some(f) => print!("  {:>6.3} ± {:<5.3}", f.mean, f.std),
                None => print!(" {:>16}", "—"),
            }
        }
        println!("   {}", short(&s.selected));
        let paper = s.paper();
        print!("{:<8} {:<7}", "", "paper");
        for (m, sd) in paper.fitness {
            print!("  {m:>6.3} ± {sd:<5.3}");
        }
        let best = (0..3).max_by(|&a, &b| paper.fitness[a].0.total_cmp(&paper.fitness[b].0)).unwrap_or(0);
        println!("   {}", KINDS[best].1);
    }
    println!("  ours: {source}; paper: the real LWR IV.");
    for s in surfaces {
        let m = &s.identified;
        println!(
            "  {}: {} samples; chosen {} with k {:.0}, λ {:.1}, surface at z = {:.4} m; maximum force {:.1} N (paper {:.0} N)",
            s.name,
            m.samples,
            s.selected,
            m.stiffness,
            m.damping,
            m.contact_position[2],
            s.max_force,
            s.paper().max_force,
        );
    }
    println!();
}

pub fn print_errors(s: &SurfaceReport, table: &str, source: &str) {
    let paper = s.paper();
    println!(
        "TABLE {table} — |command − actual| at the end of each 2 s move, {} [N] (ours: {source}; paper: the real LWR IV)",
        s.name
    );
    for (block, ratios) in RATIOS.iter().enumerate() {
        let cycles: Vec<usize> = if block == 0 { (1..CYCLES).collect() } else { vec![CYCLES] };
        if !s.commands.iter().any(|c| cycles.contains(&c.cycle)) {
            continue;
        }
        let row = |label: &str, cells: &mut dyn Iterator<Item = String>| {
            print!("{label:<18}");
            for c in cells {
                print!(" {c:>14}");
            }
            println!();
        };
        row("ratios", &mut ratios.iter().map(|r| r.to_string()));
        row("commands ours", &mut ratios.iter().map(|r| format!("{:.1}", r * s.max_force)));
        row("commands paper", &mut ratios.iter().map(|r| format!("{:.1}", r * paper.max_force)));
        for cycle in cycles {
            let of = |model: ModelUse| -> Vec<&CommandResult> {
                s.commands.iter().filter(|c| c.cycle == cycle && c.model == model).collect()
            };
            let ours = of(ModelUse::Identified);
            if ours.is_empty() {
                continue;
            }
            let pct = |e: f64, c: f64| format!("{e:.2} ({:.1}%)", e / c * 100.0);
            row(&format!("cycle #{cycle} ours"), &mut ours.iter().map(|c| pct(c.error, c.command)));
            let augmented = of(ModelUse::Augmented);
            if !augmented.is_empty() {
                let pct = |e: f64, c: f64| format!("{e:.2} ({:.2}%)", e / c * 100.0);
                row(&format!("cycle #{cycle} augm."), &mut augmented.iter().map(|c| pct(c.error, c.command)));
            }
            let paper_ratios = RATIOS[usize::from(cycle == CYCLES)];
            row(
                &format!("cycle #{cycle} paper"),
                &mut paper.errors[cycle - 1].iter().zip(paper_ratios).map(|(e, r)| pct(*e, r * paper.max_force)),
            );
        }
    }
    print!("largest error per cycle:");
    for (i, w) in s.worst_per_cycle(ModelUse::Identified).iter().enumerate().filter(|(_, w)| w.is_finite()) {
        let paper_ratios = RATIOS[usize::from(i + 1 == CYCLES)];
        let paper_worst =
            paper.errors[i].iter().zip(paper_ratios).map(|(e, r)| e / (r * paper.max_force)).fold(0.0, f64::max);
        print!("  #{} {:.1} % (paper {:.0} %)", i + 1, w * 100.0, paper_worst * 100.0);
    }
    let augmented = s.worst_per_cycle(ModelUse::Augmented);
    if augmented.iter().any(|w| w.is_finite()) {
        print!("\n  through the augmented model:");
        for (i, w) in augmented.iter().enumerate().filter(|(_, w)| w.is_finite()) {
            print!("  #{} {:.2} %", i + 1, w * 100.0);
        }
    }
    println!(
        "\n  ours: the error on the simulator's true contact force (`error` in the JSON; the sensor's reading: `error_measured`)"
    );
    println!();
}

/// What the discrepancy workflow named in a surface's identification runs, beside what the simulated
/// surface and sensor really hide.
pub fn print_discrepancy(s: &SurfaceReport, graph: bool) {
    let Some(d) = &s.discrepancy else { return };
    let against = if graph {
        "the model identified from the first graph's recording against that recording"
    } else {
        "the identified model against its own identification runs"
    };
    println!(
        "DISCREPANCY — {}: {against}, in-contact RMS {:.3} N → {:.3} N (noise floor {:.3} N; remaining: {})",
        s.name, d.rms_before, d.rms_after, d.noise_floor, d.remaining
    );
    for e in &d.named {
        let parameters: Vec<String> = e.parameters.iter().map(|(k, v)| format!("{k} {v:.4}")).collect();
        println!("  named  {:<26}{}", e.id, parameters.join(", "));
    }
    println!("  hidden {} (+ the sensor's drift since its tare)", describe(&s.simulated_surface));
    println!("  augmented model for cycle 1: {}\n", describe(&d.augmented_model));
}

/// Both tables for every surface.
pub fn print(report: &Report) {
    let source = if report.mode == "graph" {
        "simulation, node processes over DDS in real time"
    } else {
        "simulation, in-process lockstep"
    };
    print_table_one(&report.surfaces, source);
    for s in &report.surfaces {
        print_discrepancy(s, report.mode == "graph");
    }
    for s in &report.surfaces {
        print_errors(s, if s.name == "dice" { "III" } else { "II" }, source);
    }
    if let Some(arm) = &report.arm {
        super::arm::print(arm);
    }
}
