//! `softcontact demo`: the force-control paper's identification and control experiments on a simulated LWR IV, for a
//! sponge and a dice, printed in the paper's table layouts beside the paper's numbers.

mod arm;
mod case;
pub mod corpus;
mod experiment;
mod figures;
mod foreign_corpus;
mod graph;
mod paper;
mod record;
mod report;

use std::path::{Path, PathBuf};

use anyhow::Context;
use softcontact_sim::FtSensorConfig;

use experiment::{ModelUse, Plan, SurfaceRun, SurfaceSpec};
use report::{Report, SurfaceReport};

#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Output folder for the recordings, figures and tables.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Also write every table as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Run the real node processes over DDS in real time (in a loopback-only network namespace)
    /// instead of in-process lockstep.
    #[arg(long)]
    pub graph: bool,
    /// Identification runs per surface (the force-control paper: 10).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=50))]
    pub runs: u32,
    /// Force commands per surface (the force-control paper: 30, five cycles of six).
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u32).range(1..=30))]
    pub commands: u32,
    /// (internal) the --graph client for one surface, run inside the graph's namespace.
    #[arg(long, hide = true)]
    pub graph_client: Option<String>,
    /// (internal) the --graph client's second experiment, through the augmented model of the graph's
    /// parameters, its commands planned from this maximum force \[N\].
    #[arg(long, hide = true, requires = "graph_client", value_parser = crate::ranges::real(0.0, 1e6, ""))]
    pub graph_augmented: Option<f64>,
    /// With --graph: each graph under ROS 2 security (`launch-scripts/sim.sh --secure`: a keystore of its
    /// own, every process in the enclave of its name under Enforce), the client in `/user`'s enclave.
    /// Needs a build with `--features security`.
    #[arg(long, requires = "graph")]
    pub secure: bool,
    /// The --graph client's enclave on a secure graph (default: `ROS_SECURITY_ENCLAVE_OVERRIDE`, else
    /// `/`, as in ROS 2).
    #[arg(long)]
    pub enclave: Option<String>,
}

/// The force-control paper's two surfaces as the simulator makes them (with effects no model kind has).
fn surfaces() -> [SurfaceSpec; 2] {
    [
        SurfaceSpec {
            name: "sponge",
            truth: softcontact_sim::lab_sponge(),
            push: (0.01, 0.05),
            push_forces: (220.0, 80.0),
            max_force: 300.0,
            max_deformation: 0.06,
            sensor: FtSensorConfig::gamma_drifting(),
            foreign: vec![],
        },
        SurfaceSpec {
            name: "dice",
            truth: softcontact_sim::lab_dice(),
            push: (0.015, 0.07),
            push_forces: (110.0, 40.0),
            max_force: 150.0,
            max_deformation: 0.08,
            sensor: FtSensorConfig::gamma_drifting(),
            foreign: vec![],
        },
    ]
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let plan = Plan { identification_runs: args.runs as usize, commands: args.commands as usize, ..Plan::SEED_001 };
    if let Some(name) = &args.graph_client {
        let spec = surfaces().into_iter().find(|s| s.name == name).context("no such surface")?;
        let enclave = args.enclave.as_deref();
        return match args.graph_augmented {
            Some(max_force) => graph::client_augmented(&spec, plan, max_force, &args.out, enclave),
            None => graph::client(&spec, plan, &args.out, enclave),
        };
    }
    let specs = surfaces();
    let mode = if args.graph { "the node processes over DDS, real time" } else { "in-process, lockstep at 1 kHz" };
    println!("softcontact demo: the force-control paper's experiments on a simulated KUKA LWR IV ({mode}).");
    for spec in &specs {
        println!("  simulated {}: {}", spec.name, report::describe(&spec.truth));
    }
    println!("  simulated F/T sensor: ATI Gamma with white noise, bias and bias drift; tared before each experiment.");
    println!("  Every comparison below is this simulation against the paper's real robot.\n");
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    if args.graph {
        let report = graph::run(&specs, plan, &args.out, args.secure)?;
        report::print(&report);
        return write_tables(&report, args);
    }
    let epoch = softcontact_msgs::builtin_interfaces::Time::now();
    let epoch = epoch.sec as u64 * 1_000_000_000 + u64::from(epoch.nanosec);
    let started = std::time::Instant::now();
    // The two surfaces are independent cells: one thread each.
    let results: Vec<(SurfaceRun, PathBuf, softcontact_bag::WriteStats)> = std::thread::scope(|scope| {
        let handles: Vec<_> = specs
            .iter()
            .enumerate()
            .map(|(i, spec)| {
                let path = args.out.join(format!("{}.mcap", spec.name));
                scope.spawn(move || -> anyhow::Result<_> {
                    let mut recorder = record::Recorder::create(&path, epoch)?;
                    let run = experiment::run_surface(spec, plan, 1 + i as u64, &mut recorder)?;
                    Ok((run, path, recorder.finish()?))
                })
            })
            .collect();
        handles
            .into_iter()
            .zip(&specs)
            .map(|(h, spec)| {
                h.join().map_err(|_| anyhow::anyhow!("{} run panicked", spec.name))?.with_context(|| spec.name)
            })
            .collect::<anyhow::Result<_>>()
    })?;
    let wall = started.elapsed().as_secs_f64();
    let runs: Vec<&SurfaceRun> = results.iter().map(|(r, _, _)| r).collect();
    let arm = arm::run(&specs[0], 7, &args.out).context("the arm's own effects")?;
    let report = Report {
        simulation: true,
        mode: "in-process".into(),
        surfaces: runs.iter().map(|r| SurfaceReport::of(r)).collect(),
        arm: Some(arm),
    };
    report::print(&report);
    println!("simulated {:.0} s per surface in {wall:.1} s wall (both surfaces in parallel)\n", runs[0].simulated);
    let figure = |r: Result<PathBuf, Box<dyn std::error::Error>>| r.map_err(|e| anyhow::anyhow!("figure: {e}"));
    let mut written = vec![figure(figures::identification(&runs, &args.out))?];
    for (i, run) in runs.iter().enumerate() {
        written.push(figure(figures::control(run, ModelUse::Identified, 3 + i as u32, &args.out))?);
        if run.augmented.is_some() {
            written.push(figure(figures::control(run, ModelUse::Augmented, 3 + i as u32, &args.out))?);
        }
    }
    println!("recordings (ROS 2 MCAP: open in Foxglove, `softcontact identify`, `softcontact replay`):");
    for (_, path, stats) in &results {
        println!("  {} ({} messages, {:.1} MB)", path.display(), stats.messages, stats.bytes as f64 / 1e6);
    }
    println!("figures (the force-control paper's Figs. 2–4):");
    for f in &written {
        println!("  {}", f.display());
    }
    write_tables(&report, args)
}

fn write_tables(report: &Report, args: &DemoArgs) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(report)?;
    let tables = args.out.join("tables.json");
    for path in std::iter::once(&tables).chain(&args.json) {
        write(path, &text)?;
    }
    println!(
        "tables: {}{}",
        tables.display(),
        args.json.as_ref().map(|j| format!(", {}", j.display())).unwrap_or_default()
    );
    Ok(())
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// `softcontact bench demo`: wall time of both surfaces' experiments, in sequence on this thread.
pub fn bench(reps: usize) -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("softcontact-bench-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    println!("softcontact demo, in-process, both surfaces in sequence on one thread; best of {reps}");
    let mut best = [f64::INFINITY; 2];
    let mut simulated = 0.0;
    for _ in 0..reps.max(1) {
        for (i, recording) in [false, true].into_iter().enumerate() {
            let started = std::time::Instant::now();
            simulated = 0.0;
            for (k, spec) in surfaces().iter().enumerate() {
                let run = if recording {
                    let path = dir.join(format!("{}.mcap", spec.name));
                    let mut recorder = record::Recorder::create(&path, 0)?;
                    let run = experiment::run_surface(spec, Plan::SEED_001, 1 + k as u64, &mut recorder)?;
                    recorder.finish()?;
                    run
                } else {
                    experiment::run_surface(spec, Plan::SEED_001, 1 + k as u64, &mut experiment::NoObserver)?
                };
                simulated += run.simulated;
            }
            best[i] = best[i].min(started.elapsed().as_secs_f64());
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    for (label, wall) in [("experiments", best[0]), ("experiments + recording", best[1])] {
        println!(
            "{label:<26} {wall:>6.2} s wall for {simulated:.0} s simulated: {:.1} µs per 1 ms cycle, {:.0}x real time",
            wall / (simulated * 1e3) * 1e6,
            simulated / wall
        );
    }
    println!("goal: the whole demo < 30 s wall ({:.1} % of it used on one core)", best[1] / 30.0 * 100.0);
    Ok(())
}
