//! `softcontact discrepancy FILE`: where the identified contact model (or `--model`) and the recording
//! disagree, which physical effect is missing, and the augmented model that closes the gap
//! (docs/discrepancy.md; the method is `crates/discrepancy`). This command only reads the recording
//! into a [`Series`] along the contact normal, runs [`analyse`] and shows the result.

use softcontact_msgs::topics;
use std::path::PathBuf;

use anyhow::Context;
use nalgebra::Vector3;
use softcontact_bag::Recording;
use softcontact_contact::ContactModel;
use softcontact_discrepancy::{
    Options, PathOptions, PathReport, Report, Series, Wrench, analyse, name_path_effects, phases, simulate,
};
use softcontact_msgs::geometry_msgs::{PoseStamped, TwistStamped, WrenchStamped};
use softcontact_msgs::tf2_msgs::TFMessage;
use softcontact_nodes::contact_estimator::ForcePairing;
use softcontact_nodes::geometry;

use crate::identify_cmd::{self, IdentifyArgs, POSE, TF_STATIC, TWIST, WRENCH};
use crate::table::si;
use crate::{discrepancy_figures, table, tangential_paths};

#[derive(Debug, clap::Args)]
pub struct DiscrepancyArgs {
    /// The recording and how to read it, as `identify` takes them (`--json`: the design's discrepancy JSON).
    #[command(flatten)]
    pub recording: IdentifyArgs,
    /// The baseline contact model (model YAML); default: the best model identified from the recording.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// A table's undeformed surface, where its depth column reads the model's zero of deformation: a
    /// length in metres or with its unit (`812.5nm`); default: found from the force onset. The augmented
    /// model file of a table names the surface it was fitted at.
    #[arg(long, value_parser = table::parse_length, allow_hyphen_values = true)]
    pub surface: Option<f64>,
    /// Folder for the augmented model (`<name>.augmented.yaml`).
    #[arg(long, default_value = "out/discrepancy")]
    pub out: PathBuf,
    /// The recording is of loading paths (the snake paper's experiments: contacts that move sideways, each zeroed
    /// anew): name the creep of the zero, a misaligned sensor and the path dependence of the tangential force.
    #[arg(long)]
    pub loading_paths: bool,
    /// The recording is of the arm moving in free space: name its own effects (joint friction, a payload
    /// the URDF does not know) from /lwr/joint_states and /lwr/joint_torque_command.
    #[arg(long, conflicts_with = "loading_paths")]
    pub arm: bool,
    /// Replay the recording's force commands through the simulated cell (the product's nodes in lockstep
    /// with the simulator) on the baseline model and on the augmented one, and compare force, deformation
    /// and joints with the recording: RMS per signal before and after the named effects, and a figure.
    #[arg(long, conflicts_with_all = ["loading_paths", "arm"])]
    pub closed_loop: bool,
}

/// The F/T node's tares (their stamps zero the sensor's drifted offset).
const TARE: &str = topics::TARE.name;

/// Gravity in the frame of the poses (the arm's base, z up) [m/s²].
const GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// The recording along the normal from the contact position: one sample per `sample_period`, with the
/// tangential force and the change of gravity along the normal since the last tare as the sensor saw
/// them (before the first tare: since the first sample).
fn series(recording: &Recording, args: &IdentifyArgs, surface: &Vector3<f64>) -> anyhow::Result<Series> {
    let [x, y, z] = args.normal[..] else { anyhow::bail!("--normal takes three numbers") };
    let n = Vector3::new(x, y, z).normalize();
    let mut tool_to_sensor = geometry::lwr4_tool_to_sensor();
    let mut pairing = ForcePairing::new(tool_to_sensor.rotation, n, 0.05)
        .ok_or_else(|| anyhow::anyhow!("--normal must be a non-zero direction"))?;
    let (mut t, mut zs, mut zdot, mut f, mut tares) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut tangential, mut gravity) = (Vec::new(), Vec::new());
    let (mut positions, mut rotations, mut wrenches) = (Vec::new(), Vec::new(), Vec::new());
    // The sensor's orientation at the last tare, and the newest one seen.
    type Rows = [[f64; 3]; 3];
    let (mut at_tare, mut newest): (Option<Rows>, Option<Rows>) = (None, None);
    let rows = |q: &nalgebra::UnitQuaternion<f64>| -> Rows {
        let m = q.to_rotation_matrix();
        std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
    };
    for m in recording.messages() {
        let m = m?;
        match m.topic() {
            TF_STATIC => {
                let tf = m.decode::<TFMessage>()?;
                let (tool, sensor) =
                    (softcontact_dynamics::lwr4::TOOL_FRAME, softcontact_dynamics::lwr4::FT_SENSOR_FRAME);
                if let Some(pose) = geometry::static_transform(&[&tf], tool, sensor) {
                    tool_to_sensor = pose;
                    pairing.geometry.tool_to_sensor = pose.rotation;
                }
            }
            POSE => {
                let p = m.decode::<PoseStamped>()?;
                let (position, rotation) = geometry::pose_of(&p.pose);
                pairing.pose(p.header.stamp.as_secs_f64(), position, rotation);
            }
            TARE => {
                tares.push(m.decode::<WrenchStamped>()?.header.stamp.as_secs_f64());
                at_tare = newest.or(at_tare);
            }
            TWIST => {
                let t = m.decode::<TwistStamped>()?;
                pairing.twist(t.header.stamp.as_secs_f64(), geometry::vector_of(&t.twist.linear));
            }
            WRENCH => {
                let w = m.decode::<WrenchStamped>()?;
                let stamp = w.header.stamp.as_secs_f64();
                if t.last().is_some_and(|last| {
                    stamp < last + args.sample_period.unwrap_or(identify_cmd::RECORDING_SAMPLE_PERIOD) * (1.0 - 1e-6)
                }) {
                    continue;
                }
                // A reading left out as unreadable was said by `identify`, which read the same readings.
                if let Ok(p) = pairing.force(stamp, geometry::vector_of(&w.wrench.force)) {
                    t.push(stamp);
                    let contact = &pairing.geometry;
                    zs.push(contact.deformation(&p.position, surface));
                    zdot.push(contact.rate(&p.velocity));
                    f.push(p.normal_reading);
                    tangential.push(contact.across(&p.force).into());
                    let now = rows(&p.sensor_rotation);
                    newest = Some(now);
                    positions.push(p.position.into());
                    rotations.push(now);
                    let (force, torque) = (&w.wrench.force, &w.wrench.torque);
                    wrenches.push([force.x, force.y, force.z, torque.x, torque.y, torque.z]);
                    let tare = *at_tare.get_or_insert(now);
                    gravity.push(softcontact_contact::gravity_change(&now, &tare, GRAVITY, n.into()));
                }
            }
            _ => {}
        }
    }
    anyhow::ensure!(t.len() >= 100, "only {} force readings paired with a pose: too short to analyse", t.len());
    // The tool point, where the contact force acts, in the sensor frame.
    let lever = tool_to_sensor.inverse().translation.vector.into();
    let wrench =
        Wrench { normal: n.into(), position: positions, sensor_rotation: rotations, lever, measured: wrenches };
    Ok(Series::new(t, zs, zdot, f)?.with_tares(tares)?.with_sensor_inputs(tangential, gravity)?.with_wrench(wrench)?)
}

fn print_report(report: &Report, name: &str) {
    print_refit_and_effects(report, name);
    print_where(report);
    print_verdict(report);
}

/// The baseline, the noise floor, the refit and the effects named (or the rivals).
fn print_refit_and_effects(report: &Report, name: &str) {
    let n = |v: f64| si(v, "N");
    println!("{name}: baseline {} — in-contact residual RMS {}", report.baseline.kind.id(), n(report.baseline.rms));
    if let Some(c) = &report.law_rechosen {
        println!(
            "the law's kind re-chosen: {} → {} (refitted, held-out RMS {} → {}; the whole workflow on each, final \
             RMS over the record {} → {}); what follows is on {}",
            c.from.id(),
            c.to.id(),
            n(c.held_out_rms_from),
            n(c.held_out_rms_to),
            n(c.final_rms_from),
            n(c.final_rms_to),
            c.to.id()
        );
    }
    // The tare's level σ only where it differs from the floor's (noise slower than the window keeps σ).
    let level = if n(report.level_noise) == n(report.noise_floor) {
        String::new()
    } else {
        format!("; a level read over a tare's window: ± {}", n(report.level_noise))
    };
    println!(
        "noise floor {} (from {} at the refitted surface{level}); k, λ and the surface refitted: \
         {:.4e}, {:.4e}, {} → RMS {}",
        n(report.noise_floor),
        match report.noise_source {
            softcontact_discrepancy::NoiseSource::FreeSpace => "free space",
            softcontact_discrepancy::NoiseSource::FreeSpaceDifferences => "free space's consecutive differences",
            softcontact_discrepancy::NoiseSource::HoldingDifferences => "holds' consecutive differences",
            softcontact_discrepancy::NoiseSource::AllDifferences => "all consecutive differences",
        },
        report.refit.stiffness,
        report.refit.damping,
        // No value where the record does not pin the surface down, as for an effect's parameter.
        match (report.refit.contact_shift_identifiable, report.refit.contact_shift_ci) {
            (true, ci) => format!("{} ± {}", si(report.refit.contact_shift, "m"), si(ci, "m")),
            (false, ci) if ci.is_finite() =>
                format!("not identifiable (± {}, wider than the depth's span)", si(ci, "m")),
            (false, _) => "not identifiable".to_string(),
        },
        n(report.refit.rms)
    );
    if report.effects.is_empty() {
        println!("no effect named");
    } else {
        // The stages' gap is the in-contact one; free space's shows in the phases' table.
        println!("\neffects named, in order (RMS before and after each: in contact)");
        println!("{:<26}{:<48}{:>12}{:>12}", "effect", "parameters (± 95 %)", "RMS before", "RMS after");
        for e in &report.effects {
            let parameters: Vec<String> = e
                .parameters
                .iter()
                // No value where the record does not pin one down: the interval says why (the JSON keeps
                // both, with the parameter listed under `not_identifiable`).
                .map(|(k, v)| match (e.not_identifiable.contains(k), e.uncertainty.get(k)) {
                    (true, Some(u)) if u.is_finite() => format!("{k} not identifiable (± {u:.1e})"),
                    (true, _) => format!("{k} not identifiable"),
                    (false, Some(u)) => format!("{k} {v:.4e} ± {u:.1e}"),
                    (false, None) => format!("{k} {v:.4e}"),
                })
                .collect();
            println!("{:<26}{:<48}{:>12}{:>12}", e.id, parameters.join(", "), n(e.rms_before), n(e.rms_after));
        }
    }
    for b in &report.bounds {
        // The shape each family is screened over: a time constant or delay, a speed, a length, or a' itself.
        let shape = |v: f64| match b.id.as_str() {
            "viscoelastic_relaxation" | "quasi_linear_relaxation" | "time_delay" => si(v, "s"),
            "hysteresis" => si(v, "m/s"),
            "adhesion" | "squeeze_film" => si(v, "m"),
            _ => format!("{v:.2}"),
        };
        println!(
            "not named: {} at {}, an end of the range {} – {} it was screened on (a bound, not a finding); the \
             model is refitted without it",
            b.id,
            shape(b.shape),
            shape(b.range.0),
            shape(b.range.1)
        );
    }
    for a in &report.ambiguous {
        match &a.named {
            Some(named) => println!(
                "{named} named over {}, which this record fits nearly as well: {}",
                a.between[1], a.would_separate
            ),
            None => println!("ambiguous between {} and {}: {}", a.between[0], a.between[1], a.would_separate),
        }
    }
}

/// Where the gap is, before and after: by phase, speed and force, its whiteness and lag, every wrench
/// channel.
fn print_where(report: &Report) {
    let n = |v: f64| si(v, "N");
    println!("\n{:<12}{:>12}{:>12}", "phase", "RMS before", "RMS after");
    for (phase, rms) in &report.phases {
        println!("{:<12}{:>12}{:>12}", format!("{phase:?}").to_lowercase(), n(rms.rms_before), n(rms.rms_after));
    }
    let l = &report.locate;
    println!("\nwhere (in contact; before: the refitted baseline)");
    for (what, unit, bins) in [("speed", "m/s", &l.by_speed), ("force", "N", &l.by_force)] {
        for b in bins.iter() {
            println!(
                "  {what} {:>12} – {:<12}{:>12}{:>12}",
                si(b.from, unit),
                si(b.to, unit),
                n(b.rms_before),
                n(b.rms_after)
            );
        }
    }
    println!(
        "  whiteness (lag-1 autocorrelation) {:.2} → {:.2}; force against the model: best at a lag of {:+.3e} s (correlation {:.4})",
        l.whiteness_before, l.whiteness_after, l.lag_s, l.lag_correlation
    );
    if !l.channels.is_empty() {
        println!("\nevery wrench channel (sensor frame; in contact; the model's tangential law, if any, predicts F_t)");
        println!("  {:<10}{:>14}{:>14}{:>14}{:>14}", "channel", "free-space σ", "RMS before", "RMS after", "max after");
        for c in &l.channels {
            let sigma = c.noise_floor.map_or("—".to_string(), |s| format!("{s:.4}"));
            println!(
                "  {:<10}{sigma:>14}{:>14.4}{:>14.4}{:>14.4} {}",
                c.channel, c.rms_before, c.rms_after, c.max_after, c.unit
            );
        }
    }
}

/// What remains, and where most of it is.
fn print_verdict(report: &Report) {
    let remaining = match report.remaining {
        softcontact_discrepancy::Remaining::None => "none: the residual is at the noise floor",
        softcontact_discrepancy::Remaining::Unexplained => {
            "unexplained: a structured residual that no effect of the library explains"
        }
        softcontact_discrepancy::Remaining::Ambiguous => "ambiguous: the recording cannot tell the candidates apart",
    };
    if report.kept_baseline {
        println!(
            "\nthe refitted and augmented model fitted this record worse than the baseline as given: the baseline \
             stands, nothing is named"
        );
    }
    println!("\nfinal RMS {}; remaining: {remaining}", si(report.final_rms, "N"));
    let m = &report.model;
    println!(
        "its law: {}, k = {:.4e}, λ = {:.4e}, exponents a = {:.2}, b = {:.2}, c = {:.2} (SI: N, m, s), with {} effect{}{}",
        m.kind.id(),
        m.stiffness,
        m.damping,
        m.exponents.a,
        m.exponents.b,
        m.exponents.c,
        m.effects.len(),
        if m.effects.len() == 1 { "" } else { "s" },
        if report.effects.iter().any(|e| e.id == "stiffness_exponent") {
            " (the named stiffness_exponent is the law's a, its k in N/mᵃ)"
        } else {
            ""
        }
    );
    if let Some(left) = what_is_left(report) {
        println!("what is left is mostly in {left}");
    }
}

/// What the workflow found in one recording, with what it was found from.
pub struct Analysis {
    pub name: String,
    pub baseline: ContactModel,
    /// Where identify placed the undeformed surface in the world (the baseline's zero of deformation).
    pub surface: Vector3<f64>,
    /// The recording along the normal from identify's contact position.
    pub series: Series,
    pub report: Report,
    /// Read from a measurement table: the depth is along the world's z, and the model is not the arm's.
    pub from_table: bool,
}

/// A measurement table along its depth from identify's surface, its force zeroed at the free level.
fn table_analysis(args: &DiscrepancyArgs, baseline: Option<ContactModel>, say: bool) -> anyhow::Result<Analysis> {
    let id_args = &args.recording;
    let table = table::read(&id_args.file)?;
    let onset = table.onset();
    if say {
        identify_cmd::say_table(&id_args.file, &table, &onset, id_args.onset);
    }
    let found = identify_cmd::identify_table(&table, onset, id_args)?;
    let surface = args.surface.unwrap_or(found.surface);
    if say && args.surface.is_some() {
        println!("the surface at {} of the depth column (--surface)", si(surface, "m"));
    }
    let z: Vec<f64> = table.depth.iter().map(|d| d - surface).collect();
    let f: Vec<f64> = table.f.iter().map(|f| f - found.onset.free_level).collect();
    let series = Series::new(table.t.clone(), z, table.depth_rate(), f)?;
    let baseline = baseline.unwrap_or_else(|| found.id.model.model.clone());
    let report = analyse(&series, &baseline, &Options::default()).with_context(|| match args.surface {
        Some(at) => format!("with the surface at {} of the depth column (--surface)", si(at, "m")),
        None => id_args.file.display().to_string(),
    })?;
    let name = id_args.file.file_stem().and_then(|s| s.to_str()).unwrap_or("table").to_string();
    Ok(Analysis { name, baseline, surface: surface * Vector3::z(), series, report, from_table: true })
}

/// Reads the recording (or table), identifies it (or takes `--model`) and runs the workflow.
pub fn analyse_file(args: &DiscrepancyArgs, progress: bool) -> anyhow::Result<Analysis> {
    let baseline = match &args.model {
        Some(path) => {
            let text = softcontact_nodes::runtime::params::read_small(path)
                .with_context(|| format!("reading {}", path.display()))?;
            Some(ContactModel::from_yaml(&text).with_context(|| format!("{} is not a contact model", path.display()))?)
        }
        None => None,
    };
    if let Some(given) = baseline.as_ref().filter(|m| progress && !m.effects.is_empty()) {
        let ids: Vec<&str> = given.effects.iter().map(|e| e.id()).collect();
        println!(
            "the given model's effects ({}) are in its baseline residual; the refit starts from its law alone and names effects anew, and the given model stands where that refit does not fit better",
            ids.join(", ")
        );
    }
    if table::is_table(&args.recording.file) {
        return table_analysis(args, baseline, progress);
    }
    let id_args = &args.recording;
    let recording = Recording::open(&id_args.file)?;
    let said = identify_cmd::say_warnings(&recording, 0);
    let bar = if progress {
        indicatif::ProgressBar::new(recording.message_count())
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_message("identify");
    let id = identify_cmd::identify(&recording, id_args, |n| bar.set_position(n))?;
    bar.finish_and_clear();
    let surface = id.contact_position();
    let baseline = baseline.unwrap_or_else(|| id.model.model.clone());
    let series = series(&recording, id_args, &surface)?;
    identify_cmd::say_warnings(&recording, said);
    let report = analyse(&series, &baseline, &Options::default())?;
    let name = id_args.file.file_stem().and_then(|s| s.to_str()).unwrap_or("recording").to_string();
    Ok(Analysis { name, baseline, surface, series, report, from_table: false })
}

pub fn run(args: &DiscrepancyArgs) -> anyhow::Result<()> {
    if args.arm {
        let recording = Recording::open(&args.recording.file)?;
        let report = crate::arm_effects::analyse(&recording)?;
        identify_cmd::say_warnings(&recording, 0);
        crate::arm_effects::print(&report);
        let overlay = crate::arm_effects::write_overlay(&report.effects(), &args.out)?;
        println!("compensation (a --params-file overlay of the deformation controller): {}", overlay.display());
        if let Some(path) = &args.recording.json {
            let mut value = serde_json::to_value(&report)?;
            value["kind"] = serde_json::Value::from("arm");
            value["overlay_file"] = serde_json::Value::from(overlay.display().to_string());
            identify_cmd::write_json(path, &value)?;
        }
        return Ok(());
    }
    if args.loading_paths {
        let [x, y, z] = args.recording.normal[..] else { anyhow::bail!("--normal takes three numbers") };
        let recording = Recording::open(&args.recording.file)?;
        let (paths, episodes) = tangential_paths::episodes(&recording, Vector3::new(x, y, z))?;
        identify_cmd::say_warnings(&recording, 0);
        anyhow::ensure!(
            paths.len() >= 2,
            "--loading-paths needs at least two contacts that move sideways; the recording has {} contacts, {} of them sideways",
            episodes,
            paths.len()
        );
        let report = name_path_effects(&paths, &PathOptions::default())?;
        print_path_report(&report);
        if let Some(path) = &args.recording.json {
            let mut value = serde_json::to_value(&report)?;
            value["kind"] = serde_json::Value::from("loading_paths");
            value["named_ids"] = serde_json::to_value(report.names())?;
            identify_cmd::write_json(path, &value)?;
        }
        return Ok(());
    }
    if table::is_table(&args.recording.file) {
        anyhow::ensure!(
            !args.arm && !args.loading_paths && !args.closed_loop,
            "--arm, --loading-paths and --closed-loop read a ROS 2 recording, not a table"
        );
    } else {
        anyhow::ensure!(
            args.surface.is_none(),
            "--surface places a table's surface; a recording's surface is identify's, and the graph's overlay \
             (`discrepancy --out`) carries where the workflow placed it (initial_surface)"
        );
    }
    let analysis = analyse_file(args, true)?;
    let mut value = write_results(args, &analysis)?;
    // The replay comes after everything else is written: where it fails, the rest is not lost.
    let replayed = if args.closed_loop { Some(crate::closed_loop::run(args, &analysis)) } else { None };
    if let Some(Ok(result)) = &replayed {
        value["closed_loop"] = serde_json::to_value(result)?;
    }
    if let Some(path) = &args.recording.json {
        identify_cmd::write_json(path, &value)?;
    }
    match replayed {
        Some(Err(e)) => {
            Err(e.context("the closed-loop replay failed (the report, model file and figures above are written)"))
        }
        _ => Ok(()),
    }
}

/// Prints the report and writes the model file, the graph's overlay (for a recording) and the figures;
/// the JSON value of the report, naming the files.
fn write_results(args: &DiscrepancyArgs, analysis: &Analysis) -> anyhow::Result<serde_json::Value> {
    let Analysis { name, baseline, series, report, surface: analysis_surface, from_table } = analysis;
    let (name, analysis_surface, from_table) = (name.as_str(), *analysis_surface, *from_table);
    let id_args = &args.recording;
    print_report(report, name);

    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let table_surface = from_table.then(|| analysis_surface.z + report.contact_shift);
    let model_file = write_model_file(args, name, &report.model, table_surface)?;
    println!("augmented model: {}", model_file.display());
    let overlay = if from_table {
        None
    } else {
        let [x, y, z] = id_args.normal[..] else { anyhow::bail!("--normal takes three numbers") };
        let surface = analysis_surface + report.contact_shift * Vector3::new(x, y, z).normalize();
        overlay_for_the_graph(&args.out, name, &report.model, &surface)?
    };
    let at_surface = series.shifted(report.contact_shift);
    let figures = discrepancy_figures::Figures {
        name,
        series: &at_surface,
        phases: &phases(&at_surface, report.velocity_threshold),
        before: &simulate(baseline, series)?,
        after: &simulate(&report.model, &at_surface)?,
        noise_floor: report.noise_floor,
    };
    for path in discrepancy_figures::write(&args.out, &figures)? {
        let what = if path.extension().is_some_and(|e| e == "csv") { "samples" } else { "figure" };
        println!("{what}: {}", path.display());
    }
    let mut value = serde_json::to_value(report)?;
    value["model_file"] = serde_json::Value::from(model_file.display().to_string());
    if let Some(overlay) = overlay {
        value["overlay_file"] = serde_json::Value::from(overlay.display().to_string());
    }
    Ok(value)
}

/// `DIR/NAME.augmented.yaml`: the augmented model; a table's begins with a comment naming the surface
/// its fit placed (in the depth column's terms), with which `--model` starts from that fit again.
fn write_model_file(
    args: &DiscrepancyArgs,
    name: &str,
    model: &ContactModel,
    table_surface: Option<f64>,
) -> anyhow::Result<PathBuf> {
    let model_file = args.out.join(format!("{name}.augmented.yaml"));
    let mut text = model.to_yaml();
    if let Some(surface) = table_surface {
        let file = args.recording.file.display();
        text = format!(
            "# Fitted with the surface at {surface:e} m of the depth column of {file}: to start from this fit again,\n\
             # softcontact discrepancy {file} --model {} --surface {surface:e}\n{text}",
            model_file.display()
        );
        println!("its surface: {} of the depth column (--surface {surface:e})", si(surface, "m"));
    }
    std::fs::write(&model_file, text).with_context(|| format!("writing {}", model_file.display()))?;
    Ok(model_file)
}

/// [`write_overlay`], said; where the controller would refuse the model ([`ContactModel::plausible`]), that
/// is said instead and nothing else is lost (the report, the model file and the figures are written).
fn overlay_for_the_graph(
    dir: &std::path::Path,
    name: &str,
    model: &ContactModel,
    surface: &Vector3<f64>,
) -> anyhow::Result<Option<PathBuf>> {
    if let Err(e) = model.plausible() {
        println!("no parameters for the graph: the augmented model is not one the controller takes ({e})");
        // An overlay of an earlier run here would start the graph from a model not of this recording.
        let stale = dir.join(format!("{name}.params.yaml"));
        if stale.exists() {
            std::fs::remove_file(&stale).with_context(|| format!("removing {}", stale.display()))?;
            println!("removed {}, an earlier run's parameters for the graph", stale.display());
        }
        return Ok(None);
    }
    let overlay = write_overlay(dir, name, model, surface)?;
    println!("the graph's parameters for it (launch-scripts/sim.sh or robot.sh --params-file): {}", overlay.display());
    Ok(Some(overlay))
}

/// `DIR/NAME.params.yaml`: the augmented model as a parameter overlay of the graph. The controller
/// starts from it (`initial_model`, its surface placed where the workflow placed it: `initial_surface`)
/// and the estimator carries its effects in every refit (`augmented_model`), with the surface held
/// there (`surface_position`).
pub fn write_overlay(
    dir: &std::path::Path,
    name: &str,
    model: &ContactModel,
    surface: &Vector3<f64>,
) -> anyhow::Result<PathBuf> {
    model.plausible()?;
    anyhow::ensure!(surface.iter().all(|v| v.is_finite()), "the surface position is not finite");
    let model: serde_yaml_ng::Value = serde_yaml_ng::to_value(model)?;
    let section = |params: serde_yaml_ng::Value| {
        serde_yaml_ng::Value::Mapping([("ros__parameters".into(), params)].into_iter().collect())
    };
    let point = serde_yaml_ng::to_value([surface.x, surface.y, surface.z])?;
    let controller: serde_yaml_ng::Mapping =
        [("initial_model".into(), model.clone()), ("initial_surface".into(), point.clone())].into_iter().collect();
    let estimator: serde_yaml_ng::Mapping =
        [("augmented_model".into(), model), ("surface_position".into(), point)].into_iter().collect();
    let top: serde_yaml_ng::Mapping = [
        ("deformation_controller".into(), section(controller.into())),
        ("contact_estimator".into(), section(estimator.into())),
    ]
    .into_iter()
    .collect();
    let text = format!(
        "# The contact model `softcontact discrepancy` augmented with the effects it named, and where it\n\
         # placed the surface, for the graph: the controller starts from them and the estimator carries the\n\
         # effects in every refit.\n{}",
        serde_yaml_ng::to_string(&top)?
    );
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{name}.params.yaml"));
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// The loading-path workflow's answer: what it named, with the parameters and the gap before and after.
pub fn print_path_report(r: &PathReport) {
    let per_mm = softcontact_contact::N_PER_MM_1_5;
    println!(
        "Loading paths: {} contact episodes with sideways motion ({} samples), each zeroed at the third reading \
         above 0.03 N; Hertz k_n {:.3} N/mm^1.5 with the zeros {:.1} µm below the surface.",
        r.episodes,
        r.samples,
        r.k_n / per_mm,
        r.zero_depth * 1e6
    );
    println!(
        "baseline (Hertz + Walton, each episode's zero error): RMS normal {:.4} N, tangential {:.4} N",
        r.rms_before[0], r.rms_before[1]
    );
    if r.named.is_empty() {
        println!("named: none — Hertz + Walton explain the recording");
    }
    for n in &r.named {
        println!("named: {:<22} residual −{:.1} %, AICc −{:.0}", n.effect.id(), 100.0 * n.gain, n.delta_aicc);
    }
    let law = if r.names().contains(&"tangential_history") { "mindlin_deresiewicz" } else { "walton" };
    println!(
        "after: RMS normal {:.4} N, tangential {:.4} N; k_t {:.4} N/mm^1.5 ({law}), misalignment {:.3}°, creep \
         per episode {:.2} ± {:.2} µm",
        r.rms_after[0],
        r.rms_after[1],
        r.k_t / per_mm,
        r.misalignment.to_degrees(),
        r.creep_mean * 1e6,
        r.creep_sd * 1e6
    );
}

/// Where an unexplained residual is and its shape there ("unloading, around t = 32.7 s (60 % of it): an
/// offset: …"); `None` unless `remaining` is unexplained.
pub fn what_is_left(report: &Report) -> Option<String> {
    let w = report.locate.largest.filter(|_| report.remaining == softcontact_discrepancy::Remaining::Unexplained)?;
    let shape = if w.mean.abs() >= 0.7 * w.rms {
        format!(
            "an offset: the measured force {} the model by {} on average",
            if w.mean > 0.0 { "above" } else { "below" },
            si(w.mean.abs(), "N")
        )
    } else {
        format!("a wave about the model (mean {}, RMS {})", si(w.mean, "N"), si(w.rms, "N"))
    };
    let phase = match w.phase {
        softcontact_discrepancy::Phase::Free => "free space".to_string(),
        p => format!("{p:?}").to_lowercase(),
    };
    Some(format!("{phase}, around t = {:.3} s ({:.0} % of it): {shape}", w.around_s, 100.0 * w.share))
}
