//! `softcontact climb`: the snake paper's snake climbing between two walls on its rubber feet (section V of
//! "Frictional Compliance Model Development and Experiments for Snake Robot Climbing"), every set point of the gait
//! simulated, its equilibrium analysed (stability, friction cones), the choice of tangential law and
//! contact damping compared, and set points chosen badly explained. The model, gait and analysis are
//! `crates/climb`; this command prints, draws and writes them.

use std::path::{Path, PathBuf};

use anyhow::Context;
use plotters::prelude::*;
use serde::Serialize;
use softcontact_climb::gait::{self, Climb, ClimbConfig, SetPointReport};
use softcontact_contact::TangentialLaw;

use crate::loading_paths_cmd::LawArg;

#[derive(clap::Args, Debug, Clone)]
pub struct ClimbArgs {
    /// Number of links N (≥ 6: two tripods of two links and a spine of at least two).
    #[arg(long, default_value_t = 6, value_parser = crate::ranges::count(6, 40))]
    links: usize,
    /// How high to climb (m).
    #[arg(long, default_value_t = 0.05, value_parser = crate::ranges::real(0.001, 2.0, " m"))]
    height: f64,
    /// How far a tripod moves up per cycle (m).
    #[arg(long, default_value_t = 0.008, value_parser = crate::ranges::real(0.0005, 0.05, " m"))]
    step: f64,
    /// The feet's tangential law.
    #[arg(long, value_enum, default_value_t = LawArg::Walton)]
    law: LawArg,
    /// Write the SVG of the snake's configurations and forces into this folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write every table as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// One row of the comparison of tangential laws and contact damping over the squeeze and one cycle.
#[derive(Debug, Clone, Serialize)]
pub struct Variant {
    pub law: &'static str,
    pub contact_damping: bool,
    /// The smallest cone margin of any foot at any equilibrium.
    pub min_cone_margin: f64,
    /// The largest real part of any equilibrium's eigenvalues [1/s], and that mode's damping ratio.
    pub slowest_real_part: f64,
    pub damping_ratio: f64,
    pub all_stable: bool,
    pub all_sound: bool,
    /// The first reason a set point is not sound, if one is not.
    pub first_fault: Option<String>,
}

/// A set point chosen badly, and why it is not sound.
#[derive(Debug, Clone, Serialize)]
pub struct BadSetPoint {
    pub what: &'static str,
    pub sound: bool,
    pub faults: Vec<String>,
    pub report: SetPointReport,
}

#[derive(Serialize)]
struct Output<'a> {
    climb: &'a Climb,
    variants: &'a [Variant],
    bad_set_points: &'a [BadSetPoint],
}

fn law(arg: LawArg) -> TangentialLaw {
    match arg {
        LawArg::Walton => TangentialLaw::Walton,
        LawArg::MindlinDeresiewicz => TangentialLaw::MindlinDeresiewicz,
    }
}

pub fn run(args: &ClimbArgs) -> anyhow::Result<()> {
    // Each cycle climbs one step: at most a thousand of them.
    let cycles = args.height / args.step;
    anyhow::ensure!(
        cycles <= 1000.0,
        "--height {} m in steps of {} m is {cycles:.0} cycles, at most 1000",
        args.height,
        args.step
    );
    let config = ClimbConfig {
        links: args.links,
        height: args.height,
        step: args.step,
        law: law(args.law),
        ..ClimbConfig::default()
    };
    let start = std::time::Instant::now();
    let climb = gait::climb(&config).context("the climb")?;
    let wall = start.elapsed().as_secs_f64();
    print_climb(&climb, wall);
    let variants = compare(&config)?;
    print_variants(&variants);
    let bad = bad_set_points(&config)?;
    print_bad(&bad);
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let path = figure(dir, &climb)?;
        println!("figure: {}", path.display());
    }
    if let Some(path) = &args.json {
        let out = Output { climb: &climb, variants: &variants, bad_set_points: &bad };
        std::fs::write(path, serde_json::to_string_pretty(&out)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("json: {}", path.display());
    }
    anyhow::ensure!(climb.success, "the climb did not succeed: see the set points marked above");
    Ok(())
}

fn print_climb(climb: &Climb, wall: f64) {
    let c = &climb.config;
    println!(
        "The snake paper, section V: a {}-link snake ({} m, {} kg a link) between walls {:.1} mm apart, gravity along them; \
         rubber feet R {:.1} mm, kn {:.3} and kt {:.3} N/mm^1.5, mu {}, {} law; joints PD kp {} N m/rad, kd {} N m s/rad.",
        c.links,
        c.link_length,
        c.link_mass,
        climb.gap * 1e3,
        c.foot_radius * 1e3,
        c.normal_stiffness / 1e3f64.powf(1.5),
        c.tangential_stiffness / 1e3f64.powf(1.5),
        c.friction,
        c.law.id(),
        c.kp,
        c.kd
    );
    println!(
        "Every set point: simulated to rest, Newton's equilibrium, eigenvalues of the linearised closed loop (balanced), \
         a run from a start perturbed by {:.0e}; sound = stable (max Re < {:.0e} 1/s, back within {:.0e}), every cone \
         margin >= {}, no foot meant to hold slid more than {} mm, none meant to be off touching.",
        softcontact_climb::stability::PERTURBATION,
        softcontact_climb::stability::STABLE_REAL_PART,
        softcontact_climb::stability::RETURN_TOLERANCE,
        gait::MIN_MARGIN,
        gait::SLIP_TOLERANCE * 1e3
    );
    println!();
    println!(
        "{:>3}  {:<26} {:<16} {:<52} {:>6} {:>16} {:>5} {:>6} {:>7}  verdict",
        "#",
        "set point",
        "feet pressed",
        "contact forces [fn, ft] N, feet 0..N",
        "margin",
        "slowest λ [1/s]",
        "ζ",
        "slip",
        "height"
    );
    for (i, r) in climb.set_points.iter().enumerate() {
        let forces: Vec<String> = r
            .contact_forces
            .iter()
            .map(|[n, t]| if *n > 0.0 { format!("{n:.1},{t:+.1}") } else { "-".into() })
            .collect();
        let slip = r.holding.iter().map(|&f| r.slip[f]).fold(0.0, f64::max);
        let (re, im) = r.stability.slowest;
        println!(
            "{i:>3}  {:<26} {:<16} {:<52} {:>6.3} {:>16} {:>5.2} {:>4.2}mm {:>5.1}mm  {}",
            r.name,
            format!("{:?}", r.pressed),
            forces.join(" "),
            r.min_cone_margin,
            format!("{re:.2}{im:+.1}i"),
            r.stability.damping_ratio,
            slip * 1e3,
            (r.foot_height - climb.set_points[0].foot_height) * 1e3,
            if r.sound { "sound".to_string() } else { r.faults().join("; ") }
        );
    }
    println!("¹ the farthest a foot meant to hold through the move slid on the way");
    let sound = climb.set_points.iter().filter(|r| r.sound).count();
    let worst = climb.set_points.iter().map(|r| r.min_cone_margin).fold(1.0, f64::min);
    let slowest = climb.set_points.iter().map(|r| r.stability.slowest.0).fold(f64::NEG_INFINITY, f64::max);
    println!();
    println!(
        "climbed {:.1} mm (centre of mass {:.1} mm) of {:.1} mm in {} set points, {sound} sound; smallest cone margin {worst:.3}, \
         slowest mode {slowest:.2} 1/s; {:.1} s wall; {}",
        climb.climbed * 1e3,
        climb.com_climbed * 1e3,
        climb.config.height * 1e3,
        climb.set_points.len(),
        wall,
        if climb.success { "SUCCESS" } else { "FAILED" }
    );
}

/// The squeeze and one cycle under each tangential law, with and without contact damping.
fn compare(config: &ClimbConfig) -> anyhow::Result<Vec<Variant>> {
    let mut out = Vec::new();
    for law in [TangentialLaw::Walton, TangentialLaw::MindlinDeresiewicz] {
        for damping in [true, false] {
            let d = ClimbConfig::default();
            let c = ClimbConfig {
                law,
                height: config.step / 2.0,
                contact_damping: if damping { d.contact_damping } else { 0.0 },
                tangential_damping: if damping { d.tangential_damping } else { 0.0 },
                ..config.clone()
            };
            let climb = gait::climb(&c)?;
            let slowest = climb
                .set_points
                .iter()
                .max_by(|a, b| a.stability.slowest.0.total_cmp(&b.stability.slowest.0))
                .expect("a climb has set points");
            out.push(Variant {
                law: law.id(),
                contact_damping: damping,
                min_cone_margin: climb.set_points.iter().map(|r| r.min_cone_margin).fold(1.0, f64::min),
                slowest_real_part: slowest.stability.slowest.0,
                damping_ratio: slowest.stability.damping_ratio,
                all_stable: climb.set_points.iter().all(|r| r.stability.stable),
                all_sound: climb.set_points.iter().all(|r| r.sound),
                first_fault: climb
                    .set_points
                    .iter()
                    .find_map(|r| r.faults().into_iter().next().map(|f| format!("{}: {f}", r.name))),
            });
        }
    }
    Ok(out)
}

fn print_variants(variants: &[Variant]) {
    println!();
    println!("What the tangential law and contact damping do (the squeeze and one cycle):");
    println!(
        "  {:<20} {:<16} {:>14} {:>22} {:>8} {:>7}",
        "law", "contact damping", "min margin", "slowest Re λ [1/s] (ζ)", "stable", "sound"
    );
    for v in variants {
        println!(
            "  {:<20} {:<16} {:>14.3} {:>14.3} ({:.3}) {:>8} {:>7}",
            v.law,
            if v.contact_damping { "yes" } else { "none" },
            v.min_cone_margin,
            v.slowest_real_part,
            v.damping_ratio,
            v.all_stable,
            v.all_sound
        );
    }
    for v in variants {
        if let Some(f) = &v.first_fault {
            println!("  {} {}: {f}", v.law, if v.contact_damping { "with contact damping" } else { "without" });
        }
    }
}

/// Set points chosen badly: each judged the same way, with its reasons.
fn bad_set_points(config: &ClimbConfig) -> anyhow::Result<Vec<BadSetPoint>> {
    let cases: [(&'static str, ClimbConfig); 3] = [
        (
            "the feet's set points on the walls' surface: nothing squeezes",
            ClimbConfig { squeeze: 0.0, ..config.clone() },
        ),
        (
            "walls nine times as slippery (mu 0.1): the weight needs more than the cones hold",
            ClimbConfig { friction: 0.1, ..config.clone() },
        ),
        (
            "no damping anywhere: neither the contacts nor the joints",
            ClimbConfig { contact_damping: 0.0, tangential_damping: 0.0, kd: 0.0, ..config.clone() },
        ),
    ];
    let mut out = Vec::new();
    for (what, c) in cases {
        let report = gait::squeeze(&c)?;
        out.push(BadSetPoint { what, sound: report.sound, faults: report.faults(), report });
    }
    Ok(out)
}

fn print_bad(bad: &[BadSetPoint]) {
    println!();
    println!("Set points chosen badly (the squeeze, judged the same way):");
    for b in bad {
        println!("  {}: {}", b.what, if b.sound { "sound".into() } else { "NOT sound".to_string() });
        for f in &b.faults {
            println!("    - {f}");
        }
    }
}

/// The snake at the squeeze and at each set point of the first cycle and the last set point, side by
/// side between their walls, with each foot's force (2 mm per newton).
fn figure(dir: &Path, climb: &Climb) -> anyhow::Result<PathBuf> {
    let path = dir.join("climb.svg");
    let config = &climb.config;
    let snake = config.snake()?;
    let mut shown: Vec<&SetPointReport> = climb.set_points.iter().take(15).collect();
    if let Some(last) = climb.set_points.last().filter(|_| climb.set_points.len() > 15) {
        shown.push(last);
    }
    let panel = climb.gap + 0.04;
    let width_m = panel * shown.len() as f64;
    let ys: Vec<f64> = shown.iter().flat_map(|r| snake.chain.node_positions(&r.q).into_iter().map(|p| p.y)).collect();
    let (y0, y1) = (
        ys.iter().copied().fold(f64::INFINITY, f64::min) - 0.03,
        ys.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 0.03,
    );
    let scale = 1500.0; // px per metre
    let size = ((width_m * scale) as u32 + 20, ((y1 - y0) * scale) as u32 + 60);
    let root = SVGBackend::new(&path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let to_px = |k: usize, x: f64, y: f64| -> (i32, i32) {
        (10 + ((k as f64 * panel + 0.02 + x) * scale) as i32, 40 + ((y1 - y) * scale) as i32)
    };
    let title = format!(
        "climb: {} links between walls {:.1} mm apart; forces 2 mm/N (normal red, tangential blue); climbed {:.1} mm",
        config.links,
        climb.gap * 1e3,
        climb.climbed * 1e3
    );
    root.draw(&Text::new(title, (10, 10), ("sans-serif", 16).into_font()))?;
    for (k, r) in shown.iter().enumerate() {
        for x in [0.0, climb.gap] {
            root.draw(&PathElement::new(vec![to_px(k, x, y0), to_px(k, x, y1)], BLACK.stroke_width(2)))?;
        }
        let label = r.name.replace(": ", " ");
        root.draw(&Text::new(label, to_px(k, 0.0, y1 + 0.01), ("sans-serif", 10).into_font()))?;
        let nodes = snake.chain.node_positions(&r.q);
        let colour = if r.sound { RGBColor(40, 40, 40) } else { RGBColor(200, 0, 0) };
        root.draw(&PathElement::new(
            nodes.iter().map(|p| to_px(k, p.x, p.y)).collect::<Vec<_>>(),
            colour.stroke_width(3),
        ))?;
        for (f, p) in nodes.iter().enumerate() {
            let pressed = r.pressed.contains(&f);
            let foot = (config.foot_radius * scale) as i32;
            let style = if pressed { RGBColor(0, 120, 0).filled() } else { RGBColor(160, 160, 160).stroke_width(1) };
            root.draw(&Circle::new(to_px(k, p.x, p.y), foot, style))?;
            let [fn_, ft] = r.contact_forces[f];
            if fn_ > 0.0 {
                let sign = r.forces[f].wall.map_or(0.0, |w| w.normal());
                let n = 0.002 * fn_;
                root.draw(&PathElement::new(
                    vec![to_px(k, p.x, p.y), to_px(k, p.x + sign * n, p.y)],
                    RED.stroke_width(2),
                ))?;
                root.draw(&PathElement::new(
                    vec![to_px(k, p.x, p.y), to_px(k, p.x, p.y + 0.002 * ft)],
                    BLUE.stroke_width(2),
                ))?;
            }
        }
    }
    root.present()?;
    drop(root);
    Ok(path)
}

/// The climb benchmark: one stability analysis and the whole default climb, timed.
pub fn bench(reps: usize) -> anyhow::Result<()> {
    let config = ClimbConfig::default();
    let mut climber = gait::Climber::new(&config)?;
    let squeeze = gait::gait(&config, 0)?.remove(0);
    let report = climber.go(&squeeze)?;
    anyhow::ensure!(report.sound, "the squeeze is not sound: {:?}", report.faults());
    let joints = report.joints.clone();
    let (mut analysis, mut linearization, mut climb) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut set_points = 0;
    for _ in 0..reps.max(1) {
        let t = std::time::Instant::now();
        let a = softcontact_climb::stability::linearize(&climber.snake, &climber.state, &joints)?;
        let values = softcontact_climb::stability::eigenvalues(&a)?;
        linearization = linearization.min(t.elapsed().as_secs_f64());
        std::hint::black_box(values);
        let t = std::time::Instant::now();
        std::hint::black_box(softcontact_climb::stability::analyse(&climber.snake, &climber.state, &joints)?);
        analysis = analysis.min(t.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        let c = gait::climb(&config)?;
        climb = climb.min(t.elapsed().as_secs_f64());
        set_points = c.set_points.len();
    }
    println!("climb bench ({} links, best of {reps}):", config.links);
    println!("  linearisation + balanced eigenvalues (16 states): {:.3} ms", linearization * 1e3);
    println!(
        "  one stability analysis (that, and the perturbed run of {:.1} s simulated): {:.1} ms",
        report.stability.return_time,
        analysis * 1e3
    );
    println!(
        "  the whole climb of {:.0} mm: {set_points} set points in {:.2} s wall ({:.1} ms a set point)",
        config.height * 1e3,
        climb,
        climb / set_points as f64 * 1e3
    );
    Ok(())
}
