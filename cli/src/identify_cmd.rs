//! `softcontact identify FILE`: every contact model fitted to a recording, with 5-fold cross-validated
//! fitness (the force-control paper's Table I), the best chosen; JSON per docs/contracts.md. The headline fits are at
//! the estimated surface: the force-control paper's fits at the force onset carry the onset's error in the deformation
//! (k off by several % on recordings made by others), and are shown beside them.

use softcontact_msgs::topics;
use std::path::{Path, PathBuf};

use anyhow::Context;
use nalgebra::Vector3;
use serde_json::json;
use softcontact_bag::Recording;
use softcontact_contact::{ContactError, Fit, FitConfig, Kind};
use softcontact_msgs::geometry_msgs::{PoseStamped, TwistStamped, WrenchStamped};
use softcontact_msgs::tf2_msgs::TFMessage;
use softcontact_nodes::contact_estimator::EstimatorConfig;
use softcontact_nodes::contact_estimator::identify::{FramesFrom, Identification, Identifier};

use crate::table::{self, Depth, Table};
use crate::tangential_paths;

pub const WRENCH: &str = topics::WRENCH.name;
pub const POSE: &str = topics::EE_POSE.name;
pub const TWIST: &str = topics::EE_TWIST.name;
pub const TF_STATIC: &str = topics::TF_STATIC.name;
/// The most samples fitted (28 hours at 10 ms).
const MAX_WINDOW: usize = 10_000_000;

#[derive(Debug, clap::Args)]
pub struct IdentifyArgs {
    /// A ROS 2 recording (an .mcap file or a rosbag2 folder with /ft_sensor/wrench and /lwr/ee_pose), or
    /// any instrument's measurement table (.csv, .tsv, .txt, .dat: a header such as `t [s],x [nm],f [nN]`).
    pub file: PathBuf,
    /// Write the result as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Contact direction in the world, the way the hand moves to compress the surface.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_value = "0,0,-1", value_parser = crate::ranges::real(-1.0, 1.0, ""))]
    pub normal: Vec<f64>,
    /// Onset threshold of the normal force (N); default: 1 N for a recording (the force-control paper), from a table's own
    /// free part for a table (10 noise σ above its free level, at least 2 % of its force range).
    #[arg(long, value_parser = crate::ranges::real(1e-15, 1e5, " N"))]
    pub onset: Option<f64>,
    /// Time between the samples fitted (s); default: 10 ms for a recording (the force-control paper), every sample of a
    /// table.
    #[arg(long, value_parser = crate::ranges::real(1e-7, 10.0, " s"))]
    pub sample_period: Option<f64>,
}

/// The onset threshold of a recording when `--onset` does not say (the force-control paper) \[N\].
pub const RECORDING_ONSET: f64 = 1.0;
/// The sample period of a recording's fits when `--sample-period` does not say (the force-control paper) \[s\].
pub const RECORDING_SAMPLE_PERIOD: f64 = 0.01;

/// Reads the recording and identifies; `progress` is told the messages read so far.
pub fn identify(recording: &Recording, args: &IdentifyArgs, progress: impl Fn(u64)) -> anyhow::Result<Identification> {
    for topic in [WRENCH, POSE] {
        anyhow::ensure!(
            recording.topic(topic).is_some(),
            "the recording has no {topic} (it has: {})",
            recording.topics().iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    let [x, y, z] = args.normal[..] else { anyhow::bail!("--normal takes three numbers, e.g. 0,0,-1") };
    let sample_period = args.sample_period.unwrap_or(RECORDING_SAMPLE_PERIOD);
    let onset = args.onset.unwrap_or(RECORDING_ONSET);
    anyhow::ensure!(
        sample_period.is_finite() && (1e-4..=1.0).contains(&sample_period),
        "--sample-period must be between 0.0001 and 1 s for a recording"
    );
    anyhow::ensure!(onset.is_finite() && onset > 0.0, "--onset must be a positive force [N]");
    let (start, end) = recording.time_range().unwrap_or((0, 0));
    // Room for every sample of the recording (the whole contact is fitted): its duration over the
    // sample period, but never more than it has wrench readings (a summary's times may be anything) nor
    // MAX_WINDOW.
    let by_time = (end.saturating_sub(start) as f64 * 1e-9 / sample_period) as usize + 2;
    let by_readings = recording.topic(WRENCH).map_or(0, |t| t.message_count).saturating_add(2);
    let window = by_time.min(usize::try_from(by_readings).unwrap_or(usize::MAX)).clamp(1200, MAX_WINDOW);
    if by_time > MAX_WINDOW && by_readings > MAX_WINDOW as u64 {
        eprintln!("warning: the recording is longer than {MAX_WINDOW} samples: its last {MAX_WINDOW} are fitted");
    }
    let config = EstimatorConfig {
        normal: Vector3::new(x, y, z),
        sample_period,
        window,
        onset: softcontact_contact::OnsetConfig { threshold: onset, ..Default::default() },
        // A whole recording has holds: every fold scored about the mean of all the data.
        fit: FitConfig { score_about_overall_mean: true, ..Default::default() },
        ..Default::default()
    };
    let mut identifier = Identifier::new(config, 0.05)?;
    // /tf_static first, wherever it was recorded (latched, it is normally among the first messages):
    // it sets the frames for every reading.
    if recording.topic(TF_STATIC).is_some() {
        for m in recording.messages() {
            let m = m?;
            if m.topic() == TF_STATIC {
                identifier.tf_static(&m.decode::<TFMessage>()?);
                break;
            }
        }
    }
    for (i, m) in recording.messages().enumerate() {
        let m = m?;
        match m.topic() {
            WRENCH => identifier.wrench(&m.decode::<WrenchStamped>()?)?,
            POSE => identifier.pose(&m.decode::<PoseStamped>()?),
            TWIST => identifier.twist(&m.decode::<TwistStamped>()?),
            _ => {}
        }
        if i.is_multiple_of(16384) {
            progress(i as u64);
        }
    }
    if let Some(said) = identifier.unreadable.sentence() {
        eprintln!("warning: {said}");
    }
    Ok(identifier.finish()?)
}

/// A measurement table identified: the identification, what its free part said, and where the surface is
/// along the table's depth \[m\].
pub struct TableIdentification {
    pub id: Identification,
    pub onset: table::Onset,
    pub surface: f64,
}

/// Identifies a table: its force zeroed at the free level of `onset` (`Table::onset`), the onset threshold
/// from its own noise (or `--onset`), every sample fitted (or one per `--sample-period`).
pub fn identify_table(table: &Table, onset: table::Onset, args: &IdentifyArgs) -> anyhow::Result<TableIdentification> {
    anyhow::ensure!(
        args.normal == [0.0, 0.0, -1.0],
        "--normal is for recordings: a table's depth column (x or z) is already along the contact normal"
    );
    ensure_contact(table)?;
    let threshold = args.onset.unwrap_or(onset.threshold);
    let sample_period = args.sample_period.unwrap_or(0.5 * table.sample_period());
    let n = Vector3::z();
    let config = EstimatorConfig {
        normal: n,
        sample_period,
        window: (table.t.len() + 2).clamp(1200, MAX_WINDOW),
        onset: softcontact_contact::OnsetConfig { threshold, ..Default::default() },
        fit: FitConfig { score_about_overall_mean: true, ..Default::default() },
        ..Default::default()
    };
    let mut identifier = Identifier::new(config, f64::INFINITY)?;
    let rate = table.depth_rate();
    // The contact detector starts after a wave the table's free part carries beyond the threshold.
    let readings = table.t.iter().zip(&table.depth).zip(&table.f).zip(&rate).skip(onset.passed_over);
    for (((&t, &depth), &f), &rate) in readings {
        identifier.reading(t, &(depth * n), &(rate * n), f - onset.free_level)?;
    }
    let mut id = identifier.finish().map_err(|e| no_contact(e, table, &onset, threshold, args.onset.is_some()))?;
    // The identifier counts time from its first reading: the table's, after what was passed over.
    id.contact_time += table.t.get(onset.passed_over).copied().unwrap_or(0.0);
    let surface = match table.depth_is {
        Depth::Position => id.contact_position().dot(&n),
        Depth::Deformation => 0.0,
    };
    Ok(TableIdentification { id, onset, surface })
}

/// What the reader made of a table, said before its results (`onset_given`: `--onset`).
pub fn say_table(file: &Path, table: &Table, onset: &table::Onset, onset_given: Option<f64>) {
    let block = if table.block > 1 { format!(", blocks of {} rows averaged", table.block) } else { String::new() };
    println!(
        "{}: {} rows ({} samples{block}), one per {:.3e} s; depth as {}",
        file.display(),
        table.rows,
        table.t.len(),
        table.sample_period(),
        match table.depth_is {
            Depth::Position => "position (x): the surface from the force onset",
            Depth::Deformation => "deformation (z)",
        }
    );
    if table.preamble > 0 {
        println!(
            "the header is line {}: the {} lines before it are read as the instrument's preamble",
            table.preamble + 1,
            table.preamble
        );
    }
    if !table.ignored.is_empty() {
        println!("columns not read: {}", table.ignored.join(", "));
    }
    let threshold = match onset_given {
        Some(given) => format!("{} (--onset)", table.force(given)),
        None => format!("{} (10 noise σ, at least 2 % of the force range)", table.force(onset.threshold)),
    };
    if onset.free_samples > 0 {
        println!(
            "force zeroed at its free level {} (the first {} samples; their noise σ {}, which sets the onset); onset threshold {threshold}",
            table.force(onset.free_level),
            onset.free_samples,
            table.force(onset.noise),
        );
        if onset.passed_over > 0 {
            println!(
                "a wave in free space passed over: the force rose beyond the threshold in the first {} samples and fell back while the depth pressed on (no surface pushes so); the contact is looked for after it",
                onset.passed_over
            );
        }
    } else {
        let why = match onset.start {
            table::Start::Paused => "its force is flat only while the depth holds still: a pause, not free space",
            _ => "its first samples move by more than the threshold",
        };
        let zero = if onset.free_level == 0.0 {
            "the force is taken as recorded, its zero is the instrument's".to_string()
        } else {
            format!(
                "the force goes below the instrument's zero, which is then not its free level: zeroed at its least \
                 value {} (a contact only pushes)",
                table.force(onset.free_level)
            )
        };
        println!("the table starts in contact ({why}): {zero}; onset threshold {threshold}");
    }
    for doubt in table.doubts(onset.free_level) {
        eprintln!("warning: {doubt}");
    }
}

/// Whether a kind fits at all, which kinds the recording cannot tell apart, and whether the kind selected at
/// the onset is the best at the surface.
fn print_verdicts(id: &Identification, file: &Path) {
    let surface = &id.at_surface;
    let mut ranked: Vec<_> = surface.iter().filter(|f| f.fitness_mean.is_finite()).collect();
    ranked.sort_by(|a, b| b.fitness_mean.total_cmp(&a.fitness_mean));
    if !fits(id) {
        println!(
            "\nno contact model kind fits this recording (best cross-validated fitness {:.3}): the force is not \
             a function of deformation and rate alone; run `softcontact discrepancy {}` to find what is missing",
            best_fitness(id),
            file.display()
        );
    } else if let [best, second, ..] = ranked[..]
        && best.fitness_mean - second.fitness_mean < best.fitness_std.min(second.fitness_std)
    {
        println!(
            "\nnote: {} and {} fit equally well here (fitness {:.4} vs {:.4}, closer than either's std over \
             folds): the recording does not tell them apart (more, faster pushes would)",
            best.kind.label(),
            second.kind.label(),
            best.fitness_mean,
            second.fitness_mean
        );
    }
    if let Some(best) = ranked.first()
        && best.kind != id.selected()
        && let Some(chosen) = surface.iter().find(|f| f.kind == id.selected())
    {
        println!(
            "\nnote: the selection follows the fitness at the force onset (the force-control paper's rule); at the \
             estimated surface {} fits better than {} ({:.3} vs {:.3})",
            best.kind.label(),
            chosen.kind.label(),
            best.fitness_mean,
            chosen.fitness_mean
        );
    }
}

/// Below this best cross-validated fitness (at the surface) no kind explains the force: the model's
/// predictions are little better than the recording's mean force.
const FITS_AT_LEAST: f64 = 0.5;

/// The best cross-validated fitness mean at the estimated surface (−∞ when none is finite).
fn best_fitness(id: &Identification) -> f64 {
    id.at_surface.iter().map(|f| f.fitness_mean).filter(|m| m.is_finite()).fold(f64::NEG_INFINITY, f64::max)
}

/// Some kind explains the force as a function of deformation and rate.
pub fn fits(id: &Identification) -> bool {
    best_fitness(id) >= FITS_AT_LEAST
}

fn model_json(f: &Fit) -> serde_json::Value {
    json!({
        "kind": f.kind.id(),
        "stiffness": f.stiffness,
        "damping": f.damping,
        "exponents": {"a": f.exponents.a, "b": f.exponents.b, "c": f.exponents.c},
        "fitness_mean": f.fitness_mean,
        "fitness_std": f.fitness_std,
    })
}

/// `models` are fitted at the estimated surface, `models_at_onset` at the force onset (the force-control paper's
/// method); `selected_at_contact_position` (older readers) is the selected entry of `models`.
pub fn to_json(id: &Identification) -> serde_json::Value {
    let p = id.contact_position();
    let selected = id.at_surface.iter().find(|f| f.kind == id.selected()).map(model_json);
    json!({
        "selected": id.selected().id(),
        "contact_position": [p.x, p.y, p.z],
        "fits": fits(id),
        "models": id.at_surface.iter().map(model_json).collect::<Vec<_>>(),
        "models_at_onset": id.model.estimate.fits.iter().map(model_json).collect::<Vec<_>>(),
        "selected_at_contact_position": selected,
        "samples": id.samples,
        "frames": match id.frames { FramesFrom::TfStatic => "tf_static", FramesFrom::Urdf => "urdf" },
    })
}

/// The force-control paper's Table I layout (fitness mean ± std per kind), at the estimated surface and at the onset,
/// then each kind's parameters at both.
pub fn print_table(id: &Identification, file: &Path, from_table: bool) {
    let name = file.file_stem().and_then(|s| s.to_str()).unwrap_or("recording");
    let short = |k: Kind| match k {
        Kind::KelvinVoigt => "linear K/V",
        Kind::HuntCrossley => "non-linear H/C",
        Kind::AzadFeatherstone => "non-linear A/F",
        other => other.id(),
    };
    let (surface, onset) = (&id.at_surface, &id.model.estimate.fits);
    println!("Fitness (the force-control paper's eq. 18), 5-fold cross-validated, mean ± std over folds:");
    print!("{:<28}", "");
    for f in surface {
        print!("{:>18}", short(f.kind));
    }
    println!();
    for (label, fits) in
        [(format!("{name}, at the surface"), surface), ("  at the onset (the force-control paper)".into(), onset)]
    {
        print!("{label:<28}");
        for f in fits {
            let mark = if f.kind == id.selected() { "*" } else { " " };
            print!("{:>17}{mark}", format!("{:.3} ± {:.3}", f.fitness_mean, f.fitness_std));
        }
        println!();
    }
    let p = id.contact_position();
    if from_table {
        println!("\nat the estimated surface:");
    } else {
        println!("\nat the estimated surface [{:.4e}, {:.4e}, {:.4e}] m:", p.x, p.y, p.z);
    }
    print_parameters(surface);
    println!(
        "\nat the force onset, {} from the surface (the force-control paper's method):",
        crate::table::si(id.model.offset.abs(), "m")
    );
    print_parameters(onset);
    print_verdicts(id, file);
    let m = &id.model.model;
    if from_table {
        println!(
            "\nselected: {} (* above), its fit at the estimated surface: k = {:.4e}, λ = {:.4e} (SI: N, m, s)",
            id.selected().label(),
            m.stiffness,
            m.damping
        );
        println!("{} samples in contact from t = {:.3} s", id.samples, id.contact_time);
        return;
    }
    println!(
        "\nselected: {} (* above); at the estimated surface [{:.4e}, {:.4e}, {:.4e}] m: k = {:.4e}, λ = {:.4e}",
        id.selected().label(),
        p.x,
        p.y,
        p.z,
        m.stiffness,
        m.damping
    );
    println!(
        "{} samples in contact from t = {:.3} s; {} readings paired, {} without a fresh pose; frames from {}",
        id.samples,
        id.contact_time,
        id.readings,
        id.unpaired,
        match id.frames {
            FramesFrom::TfStatic => TF_STATIC,
            FramesFrom::Urdf => "the URDF (no /tf_static in the recording)",
        }
    );
}

fn print_parameters(fits: &[Fit]) {
    println!("  {:<22}{:>12}{:>12}{:>7}{:>7}{:>7}", "model", "k", "λ", "a", "b", "c");
    for f in fits {
        let held = match (f.stiffness_held, f.damping_held) {
            (false, false) => "",
            (true, false) => "  (k not excited by the data: kept at its starting value)",
            (false, true) => "  (λ not excited by the data: kept at its starting value)",
            (true, true) => "  (k, λ not excited by the data: kept at their starting values)",
        };
        println!(
            "  {:<22}{:>12.4e}{:>12.4e}{:>7.2}{:>7.2}{:>7.2}{held}",
            f.kind.label(),
            f.stiffness,
            f.damping,
            f.exponents.a,
            f.exponents.b,
            f.exponents.c
        );
    }
}

/// Prints the recording's warnings after the first `said` (what opening it recovered, then the damage
/// reading it found: a chunk skipped); the number said so far. Every command that reads a recording
/// says so after each pass over it.
pub fn say_warnings(recording: &Recording, said: usize) -> usize {
    let warnings = recording.warnings();
    for w in warnings.iter().skip(said) {
        eprintln!("warning: {w}");
    }
    warnings.len().max(said)
}

/// Why a table's identification found no contact, in the table's terms: the threshold and the free level,
/// and how many samples in a row rose above it where some did.
fn no_contact(e: ContactError, table: &Table, onset: &table::Onset, threshold: f64, given: bool) -> anyhow::Error {
    let confirm = softcontact_contact::OnsetConfig::default().confirm;
    let above = table.longest_above(onset.free_level, threshold);
    let rose = if above == 0 {
        format!("no force rose {} above the free level {}", table.force(threshold), table.force(onset.free_level))
    } else {
        format!(
            "the force rose more than {} above the free level {} on at most {above} sample{} in a row; a contact needs {confirm}",
            table.force(threshold),
            table.force(onset.free_level),
            if above == 1 { "" } else { "s" }
        )
    };
    let why = if given { " given" } else { ": 10 noise σ, at least 2 % of the force range" };
    anyhow::anyhow!("{e}: {rose} (the onset threshold{why}); set another with --onset [N]")
}

/// A table of deformations must reach z > 0 somewhere; one of positions has its surface found at the
/// force onset, which [`identify_table`] reports when there is none.
fn ensure_contact(table: &Table) -> anyhow::Result<()> {
    let (least, most) = table::extent(&table.f);
    anyhow::ensure!(
        most > least,
        "the force is {} on every row: nothing touches, or the column holds no measurement",
        table.force(most)
    );
    anyhow::ensure!(
        table.depth_is == Depth::Position || table.depth.iter().any(|&z| z > 0.0),
        "no sample is in contact: the deformation column z never exceeds 0 (z > 0 compresses, the surface at \
         z = 0); a column of positions is named x, and its surface is found at the force onset"
    );
    Ok(())
}

fn run_table(args: &IdentifyArgs) -> anyhow::Result<()> {
    let table = table::read(&args.file)?;
    ensure_contact(&table)?;
    let onset = table.onset();
    say_table(&args.file, &table, &onset, args.onset);
    let found = identify_table(&table, onset, args)?;
    println!(
        "surface at {} {} along the table's depth\n",
        if table.depth_is == Depth::Position { "x =" } else { "z =" },
        table.length(found.surface)
    );
    print_table(&found.id, &args.file, true);
    if let Some(path) = &args.json {
        let mut value = to_json(&found.id);
        value["surface"] = json!(found.surface);
        value["free_level"] = json!(found.onset.free_level);
        value["onset_threshold"] = json!(args.onset.unwrap_or(found.onset.threshold));
        write_json(path, &value)?;
    }
    Ok(())
}

pub fn run(args: &IdentifyArgs) -> anyhow::Result<()> {
    if table::is_table(&args.file) {
        return run_table(args);
    }
    let recording = Recording::open(&args.file)?;
    let said = say_warnings(&recording, 0);
    let bar = indicatif::ProgressBar::new(recording.message_count());
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} messages ({eta})")
            .expect("template")
            .progress_chars("=> "),
    );
    bar.set_message("identify");
    let normal = identify(&recording, args, |n| bar.set_position(n));
    bar.finish_and_clear();
    let [x, y, z] = args.normal[..] else { anyhow::bail!("--normal takes three numbers, e.g. 0,0,-1") };
    // The tangential law is told besides, where the contacts move sideways; what it cannot read (a
    // non-finite sample) leaves the normal law's answer standing.
    let tangential = match tangential_paths::from_recording(&recording, Vector3::new(x, y, z)) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("warning: tangential law not identified: {e:#}");
            None
        }
    };
    // Damage found while reading (a chunk skipped).
    say_warnings(&recording, said);
    // A recording of sideways pushes (the snake paper's loading paths) may hold too little of the normal law's
    // kind of excitation for the normal fits: its tangential law is reported all the same.
    let normal = match (normal, &tangential) {
        (Ok(id), _) => Some(id),
        (Err(e), Some(_)) => {
            println!("Normal law: not identified ({e:#})\n");
            None
        }
        (Err(e), None) => return Err(e),
    };
    if let Some(id) = &normal {
        print_table(id, &args.file, false);
    }
    if let Some(t) = &tangential {
        println!();
        tangential_paths::print(t);
    }
    if let Some(path) = &args.json {
        let mut value = normal.as_ref().map_or_else(|| json!({}), to_json);
        value["tangential"] = tangential.as_ref().map_or(serde_json::Value::Null, tangential_paths::to_json);
        write_json(path, &value)?;
    }
    Ok(())
}

pub fn write_json(path: &Path, value: &serde_json::Value) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(value)? + "\n")
        .with_context(|| format!("writing {}", path.display()))
}
