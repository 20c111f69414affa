//! `softcontact bench`: ns per call of the hot paths, timed the way the Pinocchio reference program is
//! (pre-drawn random states, many calls cycling through them, best of several repetitions), so that the
//! two can be compared in one run. Pin the process to one core for stable numbers: `taskset -c 1 …`.

use softcontact_msgs::topics;
use std::hint::black_box;
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};
use nalgebra::Matrix6xX;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use softcontact_contact::{
    DampingExponent, FitConfig, Kind, Sample, WindowEstimator, estimate_contact_offset, estimate_exponent,
};
use softcontact_dynamics::{Axes, Model, lwr4};

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// `softcontact demo` in-process: both surfaces' full experiments one after the other on one
    /// thread, without and with the recording (goal: the demo < 30 s wall).
    Demo {
        #[arg(long, default_value_t = 3, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
    },
    /// The whole graph over DDS, plain and under ROS 2 security in the same run: the FRI loop's answer
    /// latency and each process's CPU (the secure column needs the `security` feature).
    Graph {
        /// Measured seconds of each graph run.
        #[arg(long, default_value_t = 20.0, value_parser = crate::ranges::real(1.0, 3600.0, " s"))]
        seconds: f64,
        /// Seconds before the measurement (discovery, the handshakes, the hand reaching the sponge).
        #[arg(long, default_value_t = 8.0, value_parser = crate::ranges::real(0.0, 600.0, " s"))]
        settle: f64,
        /// Runs of each; the median is kept.
        #[arg(long, default_value_t = 3, value_parser = crate::ranges::count(1, 100))]
        reps: usize,
    },
    /// Rigid-body dynamics: FK + Jacobian, RNEA, CRBA, g, h, forward dynamics and a whole control tick.
    Dynamics {
        /// Calls per repetition.
        #[arg(long, default_value_t = 1_000_000, value_parser = crate::ranges::count(1, 100_000_000))]
        calls: usize,
        /// Repetitions; the best is kept.
        #[arg(long, default_value_t = 5, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
        /// Also time Pinocchio's C++ on the same URDF (builds it once: needs `pip install pin
        /// cmeel-eigen cmeel-urdfdom-headers` and g++) and print our/Pinocchio ratios.
        #[arg(long)]
        pinocchio: bool,
        /// Write the table as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// The simulator's real-time factor: arm, KRC, soft surface and F/T sensor at 1 kHz, in-process,
    /// with every FRI measurement and RDT record encoded as the wire carries them.
    Sim {
        /// Simulated seconds per repetition.
        #[arg(long, default_value_t = 10.0, value_parser = crate::ranges::real(0.001, 3600.0, " s"))]
        seconds: f64,
        #[arg(long, default_value_t = 3, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
    },
    /// The FRI driver's work per cycle: decode the measurement, decide the reply, compute the tool pose
    /// and twist it publishes, encode the reply.
    Driver {
        #[arg(long, default_value_t = 200_000, value_parser = crate::ranges::count(1, 100_000_000))]
        calls: usize,
        #[arg(long, default_value_t = 5, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
    },
    /// The snake paper's 205 loading paths in-process: the arm as the stage (driver, F/T node, stage and simulator
    /// in lockstep) against the ideal stage in the same run (goal: < 60 s wall), and the stage's update
    /// per 1 ms tick.
    LoadingPaths {
        #[arg(long, default_value_t = 3, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
        /// Stage updates per repetition.
        #[arg(long, default_value_t = 100_000, value_parser = crate::ranges::count(1, 100_000_000))]
        calls: usize,
    },
    /// The snake paper's climbing snake: one stability analysis (linearisation, balanced eigenvalues, the run
    /// from a perturbed start) and the whole default climb.
    Climb {
        #[arg(long, default_value_t = 3, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
    },
    /// The deformation controller's tick in contact: FK, J, J̇q̇, M, M⁻¹, h, the deformation law, eq. 15
    /// and the limiter.
    Controller {
        #[arg(long, default_value_t = 200_000, value_parser = crate::ranges::count(1, 100_000_000))]
        calls: usize,
        #[arg(long, default_value_t = 5, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
    },
    /// Contact estimation: sliding-window update per sample, full refit of every kind with 5-fold
    /// cross-validation over the window, exponent and contact-offset estimation.
    Contact {
        /// Samples in the window (the force-control paper: 1200).
        #[arg(long, default_value_t = 1200, value_parser = crate::ranges::count(10, 1_000_000))]
        window: usize,
        /// Repetitions; the best is kept.
        #[arg(long, default_value_t = 5, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Recordings: writing a 1 kHz, 6-topic recording (as `softcontact record` does, a flush a second)
    /// and reading it back with `softcontact identify`'s whole work (decode, pair, fit every kind).
    Recording {
        /// Recorded seconds.
        #[arg(long, default_value_t = 60.0, value_parser = crate::ranges::real(0.001, 3600.0, " s"))]
        seconds: f64,
        #[arg(long, default_value_t = 3, value_parser = crate::ranges::count(1, 1000))]
        reps: usize,
    },
    /// The discrepancy workflow: its hidden-effect corpus made in the lockstep cell (the detection table
    /// and the goals), and the whole workflow's time on a 1 kHz recording (one thread, and a second for the delay's screen where there is a second core).
    Discrepancy {
        /// Threads for the corpus (each case is an independent cell).
        #[arg(long, default_value_t = 2, value_parser = crate::ranges::count(1, 64))]
        threads: usize,
        /// Write the corpus outcomes and the timing as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Only the timing, not the corpus.
        #[arg(long)]
        timing_only: bool,
        /// Only the corpus cases whose name contains this text (and no timing).
        #[arg(long)]
        case: Option<String>,
        /// Keep each case's recording in this folder (`case<seed>.mcap`) to run `softcontact discrepancy` on.
        #[arg(long)]
        keep: Option<PathBuf>,
        /// Instead of the corpus: the measured curves of this folder (e.g. `data/afm`) against its
        /// `expected.json` (the table of `docs/discrepancy-real.md`).
        #[arg(long)]
        real: Option<PathBuf>,
        /// Seeds of each null whose noise is not white (coloured noise, a wandering offset, a slow drift);
        /// the committed table uses 2.
        #[arg(long, default_value_t = 2, value_parser = crate::ranges::count(1, 100))]
        slow_noise_seeds: usize,
        /// Only the foreign-effect corpus (effects written outside the library), not today's corpus nor
        /// the timing.
        #[arg(long)]
        foreign: bool,
    },
}

/// Name, what Pinocchio calls it, and the goal ratio (ours / Pinocchio) where the project set one.
const TERMS: [(&str, &str, Option<f64>); 8] = [
    ("fk_jacobian", "computeFrameJacobian (FK + J of lwr_tool)", None),
    ("rnea", "rnea", Some(0.5)),
    ("crba", "crba", Some(1.0)),
    ("gravity", "computeGeneralizedGravity", None),
    ("nonlinear_effects", "nonLinearEffects", None),
    ("aba", "aba (ours: CRBA + Cholesky)", None),
    ("minverse", "computeMinverse (ours: CRBA + Cholesky + inverse)", None),
    ("control_tick", "computeAllTerms (ours: FK, J, J̇q̇, M, M⁻¹, h)", Some(1.0)),
];

fn best_ns(calls: usize, reps: usize, mut f: impl FnMut(usize)) -> f64 {
    (0..reps)
        .map(|_| {
            let start = Instant::now();
            for i in 0..calls {
                f(i);
            }
            start.elapsed().as_nanos() as f64 / calls as f64
        })
        .fold(f64::INFINITY, f64::min)
}

fn time_ours(model: &Model, calls: usize, reps: usize) -> anyhow::Result<Vec<f64>> {
    const STATES: usize = 1000;
    let n = model.dof();
    let mut rng = SmallRng::seed_from_u64(7);
    let mut draw = |lo: f64, hi: f64| -> Vec<Vec<f64>> {
        (0..STATES).map(|_| (0..n).map(|_| rng.random_range(lo..hi)).collect()).collect()
    };
    let q: Vec<Vec<f64>> = {
        let mut rng = SmallRng::seed_from_u64(8);
        (0..STATES)
            .map(|_| {
                model
                    .joints
                    .iter()
                    .map(|j| {
                        rng.random_range(
                            j.limits.lower.max(-std::f64::consts::PI)..j.limits.upper.min(std::f64::consts::PI),
                        )
                    })
                    .collect()
            })
            .collect()
    };
    let (dq, ddq, tau) = (draw(-1.0, 1.0), draw(-1.0, 1.0), draw(-10.0, 10.0));
    let tool = model.frame_id(lwr4::TOOL_FRAME)?;
    let mut data = model.data();
    let mut jac = Matrix6xX::zeros(n);
    let k = |i: usize| i % STATES;
    // Check once that every term succeeds before timing it.
    model.forward_dynamics(&mut data, &q[0], &dq[0], &tau[0], None)?;
    Ok(vec![
        best_ns(calls, reps, |i| {
            model.forward_kinematics(&mut data, &q[k(i)]);
            model.frame_jacobian(&data, tool, Axes::World, &mut jac);
            black_box(jac[(0, 0)]);
        }),
        best_ns(calls, reps, |i| {
            black_box(model.rnea(&mut data, &q[k(i)], &dq[k(i)], &ddq[k(i)], None)[0]);
        }),
        best_ns(calls, reps, |i| {
            black_box(model.mass_matrix(&mut data, &q[k(i)])[(0, 0)]);
        }),
        best_ns(calls, reps, |i| {
            black_box(model.gravity_torques(&mut data, &q[k(i)])[0]);
        }),
        best_ns(calls, reps, |i| {
            black_box(model.nonlinear_effects(&mut data, &q[k(i)], &dq[k(i)])[0]);
        }),
        best_ns(calls, reps, |i| {
            black_box(model.forward_dynamics(&mut data, &q[k(i)], &dq[k(i)], &tau[k(i)], None).map(|a| a[0]).ok());
        }),
        best_ns(calls, reps, |i| {
            black_box(model.mass_matrix_inverse(&mut data, &q[k(i)]).map(|m| m[(0, 0)]).ok());
        }),
        best_ns(calls, reps, |i| {
            black_box(
                model.control_terms(&mut data, &q[k(i)], &dq[k(i)], tool).map(|t| t.mass_matrix_inverse[(0, 0)]).ok(),
            );
        }),
    ])
}

fn time_pinocchio(calls: usize, reps: usize) -> anyhow::Result<serde_json::Value> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../crates/dynamics/benches/pinocchio/run.sh");
    let urdf = std::env::temp_dir().join(format!("softcontact-bench-{}.urdf", std::process::id()));
    std::fs::write(&urdf, lwr4::URDF)?;
    eprintln!("timing Pinocchio's C++ ({})", script.display());
    let out = Command::new("bash").arg(&script).arg(&urdf).arg(calls.to_string()).arg(reps.to_string()).output();
    let _ = std::fs::remove_file(&urdf);
    let out = out.with_context(|| format!("cannot run {}", script.display()))?;
    if !out.status.success() {
        bail!("the Pinocchio benchmark failed:\n{}", String::from_utf8_lossy(&out.stderr));
    }
    serde_json::from_slice(&out.stdout).context("the Pinocchio benchmark printed no JSON")
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Dynamics { calls, reps, pinocchio, json } => run_dynamics(calls, reps, pinocchio, json),
        BenchCommand::Contact { window, reps, json } => run_contact(window, reps, json),
        BenchCommand::Sim { seconds, reps } => run_sim(seconds, reps),
        BenchCommand::Graph { seconds, settle, reps } => crate::bench_graph::run(seconds, settle, reps),
        BenchCommand::Driver { calls, reps } => run_driver(calls, reps),
        BenchCommand::Controller { calls, reps } => run_controller(calls, reps),
        BenchCommand::LoadingPaths { reps, calls } => run_loading_paths(reps, calls),
        BenchCommand::Climb { reps } => crate::climb_cmd::bench(reps),
        BenchCommand::Recording { seconds, reps } => run_recording(seconds, reps),
        BenchCommand::Demo { reps } => crate::demo::bench(reps),
        BenchCommand::Discrepancy { real: Some(dir), json, .. } => {
            let outcomes = crate::real_curves::run(&dir)?;
            crate::real_curves::print(&outcomes);
            if let Some(path) = json {
                crate::identify_cmd::write_json(&path, &crate::real_curves::to_json(&outcomes))?;
            }
            Ok(())
        }
        BenchCommand::Discrepancy { threads, json, timing_only, case, keep, real: None, slow_noise_seeds, foreign } => {
            let corpora = crate::demo::corpus::Corpora { timing_only, foreign_only: foreign, slow_noise_seeds };
            crate::demo::corpus::bench(threads, json, corpora, case.as_deref(), keep.as_deref())
        }
    }
}

/// Writes `seconds` of 1 kHz data on the six 1 kHz topics of the graph, flushing every second.
fn write_recording(
    path: &std::path::Path,
    readings: &[softcontact_nodes::contact_estimator::identify::SyntheticReading],
) -> anyhow::Result<u64> {
    use softcontact_bag::BagWriter;
    use softcontact_msgs::geometry_msgs::TransformStamped;

    use softcontact_msgs::tf2_msgs::TFMessage;
    let mut w = BagWriter::create(path)?;
    let js = w.add(&topics::JOINT_STATES)?;
    let pose = w.add(&topics::EE_POSE)?;
    let twist = w.add(&topics::EE_TWIST)?;
    let tf = w.add(&topics::TF)?;
    let raw = w.add(&topics::WRENCH_RAW)?;
    let wrench = w.add(&topics::WRENCH)?;
    let mut next_flush = 1.0;
    let mut transform = TFMessage { transforms: vec![TransformStamped::default()] };
    for r in readings {
        let ns = (1.7e18 + r.t * 1e9) as u64;
        w.write(js, ns, &r.joint_state)?;
        w.write(pose, ns, &r.pose)?;
        w.write(twist, ns, &r.twist)?;
        let t = &mut transform.transforms[0];
        t.header = r.pose.header.clone();
        t.child_frame_id.clear();
        t.child_frame_id.push_str("lwr_tool");
        t.transform.translation = softcontact_msgs::geometry_msgs::Vector3 {
            x: r.pose.pose.position.x,
            y: r.pose.pose.position.y,
            z: r.pose.pose.position.z,
        };
        t.transform.rotation = r.pose.pose.orientation;
        w.write(tf, ns, &transform)?;
        w.write(raw, ns, &r.wrench)?;
        w.write(wrench, ns, &r.wrench)?;
        if r.t >= next_flush {
            w.flush()?;
            next_flush += 1.0;
        }
    }
    Ok(w.finish()?.messages)
}

fn run_recording(seconds: f64, reps: usize) -> anyhow::Result<()> {
    anyhow::ensure!(seconds > 1.0 && reps > 0, "--seconds > 1 and --reps > 0");
    let model = softcontact_sim::sponge();
    let readings =
        softcontact_nodes::contact_estimator::identify::synthetic_pushes(&model, 0.3, 0.03, seconds, 1000.0, 0.2, 1)?;
    let dir = std::env::temp_dir().join(format!("softcontact-bench-recording-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let (mut write_s, mut read_s) = (f64::INFINITY, f64::INFINITY);
    let mut messages = 0;
    let mut selected = String::new();
    for rep in 0..reps {
        let path = dir.join(format!("run{rep}.mcap"));
        let start = Instant::now();
        messages = write_recording(&path, &readings)?;
        write_s = write_s.min(start.elapsed().as_secs_f64());
        let args = crate::identify_cmd::IdentifyArgs {
            file: path.clone(),
            json: None,
            normal: vec![0.0, 0.0, -1.0],
            onset: None,
            sample_period: Some(0.01),
        };
        let start = Instant::now();
        let recording = softcontact_bag::Recording::open(&path)?;
        let id = crate::identify_cmd::identify(&recording, &args, |_| {})?;
        read_s = read_s.min(start.elapsed().as_secs_f64());
        selected = id.selected().id().to_string();
    }
    let bytes = std::fs::metadata(dir.join("run0.mcap"))?.len();
    std::fs::remove_dir_all(&dir)?;
    println!(
        "recording: {seconds} s at 1 kHz on 6 topics = {messages} messages, {:.1} MB (zstd chunks), best of {reps}",
        bytes as f64 / 1e6
    );
    println!(
        "  write (encode CDR, chunk, compress, index, flush a second): {:.3} s = {:.0} messages/s; \
         at 1 kHz that is {:.2} % of one core (goal < 2 %)",
        write_s,
        messages as f64 / write_s,
        100.0 * write_s / seconds
    );
    println!(
        "  read + identify (open, decompress, decode, pair, fit every kind with 5-fold CV): {read_s:.3} s (goal < 0.5 s \
         for 60 s); chose {selected} (the data's: {})",
        model.kind.id()
    );
    Ok(())
}

/// Times `DeformationController::tick` on states of a hand pressing the simulated sponge.
fn run_loading_paths(reps: usize, calls: usize) -> anyhow::Result<()> {
    use crate::loading_paths_arm::{HiddenErrors, run};
    use crate::loading_paths_cmd::{LawArg, specimen};
    if calls == 0 || reps == 0 {
        bail!("--calls and --reps must be positive");
    }
    let truth = specimen(LawArg::MindlinDeresiewicz);
    let paths = softcontact_contact::seed_000_experiments(&truth, 2e-3)?;
    let hidden = HiddenErrors { creep_sd: 5e-6, misalignment: 0.5f64.to_radians(), noise: 0.005, seed: 0 };
    let (mut arm, mut ideal, mut simulated) = (f64::INFINITY, f64::INFINITY, 0.0);
    for _ in 0..reps {
        let start = Instant::now();
        simulated = black_box(run(&truth, &paths, &hidden)?).simulated;
        arm = arm.min(start.elapsed().as_secs_f64());
        let start = Instant::now();
        let mut bench = softcontact_sim::SpecimenBench::new(softcontact_sim::SpecimenConfig {
            creep_sd: hidden.creep_sd,
            misalignment: hidden.misalignment,
            noise: hidden.noise,
            ..softcontact_sim::SpecimenConfig::seed_000(truth.clone(), 0)
        })?;
        for p in &paths {
            black_box(bench.run(p)?);
        }
        ideal = ideal.min(start.elapsed().as_secs_f64());
    }
    println!(
        "205 loading paths: arm as the stage {arm:.2} s wall for {simulated:.0} s simulated ({:.0}x real time; goal < 60 s), \
         ideal stage {:.1} ms: the arm costs {:.0}x the ideal stage",
        simulated / arm,
        ideal * 1e3,
        arm / ideal
    );
    // The stage's update alone, the tool moving down 1 µm per tick.
    let model = softcontact_dynamics::lwr4::model();
    let tool = model.frame_id(softcontact_dynamics::lwr4::TOOL_FRAME)?;
    let q = softcontact_sim::DEFAULT_Q;
    let mut stage = softcontact_control::PositionStage::new(model, tool, &q, 150.0);
    let start_position = stage.tool_position(&q);
    let (velocity, force) = (nalgebra::Vector3::new(0.0, 0.0, -1e-3), nalgebra::Vector3::new(0.0, 0.0, 20.0));
    let ns = best_ns(calls, reps, |i| {
        let reference = start_position + velocity * (1e-3 * (i % 1000) as f64);
        black_box(stage.update(&q, &[0.0; 7], &reference, &velocity, &force, 1e-3).ok());
    });
    println!(
        "stage update per tick (inverse kinematics, two Newton steps; inverse dynamics): {ns:.0} ns (goal < 10 µs)"
    );
    Ok(())
}

fn run_controller(calls: usize, reps: usize) -> anyhow::Result<()> {
    use nalgebra::Vector3;
    use softcontact_nodes::deformation_controller::{ControllerConfig, DeformationController};
    if calls == 0 || reps == 0 {
        bail!("--calls and --reps must be positive");
    }
    // A descent onto the surface: states the controller sees around contact.
    let mut q = softcontact_sim::DEFAULT_Q;
    let dq = [0.0, 0.01, 0.0, -0.02, 0.0, 0.01, 0.0];
    let mut states = Vec::new();
    for i in 0..2000 {
        q[1] += 1e-5;
        q[3] -= 2e-5;
        let f = if i > 500 { (i - 500) as f64 * 0.1 } else { 0.0 };
        states.push((q, dq, f));
    }
    // The plain sponge (the force-control paper's inverse), and the lab sponge's augmented model (two relaxation
    // branches, hysteresis: the effects' states every tick, the hold re-solved every tick after the move).
    let mut results = Vec::new();
    for (label, model) in
        [("plain model", softcontact_sim::sponge()), ("augmented model", softcontact_sim::lab_sponge())]
    {
        let mut controller = DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), model)?;
        // The joint states' clock, a millisecond a tick.
        let mut time = 0.0;
        for (q, dq, f) in &states {
            time += 1e-3;
            controller.tick(time, q, dq, *f, &Vector3::new(0.0, 0.0, *f))?;
        }
        let command_ns = best_ns(200, reps, |i| {
            black_box(controller.command_force(100.0 + (i % 40) as f64, 2.0).ok());
        });
        controller.command_force(140.0, 2.0)?;
        let ns = best_ns(calls, reps, |i| {
            let (q, dq, f) = &states[500 + i % 1500];
            time += 1e-3;
            black_box(controller.tick(time, q, dq, *f, &Vector3::new(0.0, 0.0, *f)).map(|(t, _)| t[0]).ok());
        });
        println!(
            "deformation controller, {label}: tick in contact (all dynamics terms, eq. 15, limits) {ns:.0} ns \
             (goal < 10 µs); a force command {:.1} µs",
            command_ns / 1e3
        );
        results.push((ns, command_ns));
    }
    println!(
        "the augmented model costs {:.2}x the plain tick and {:.0}x the plain command (its move is simulated)",
        results[1].0 / results[0].0,
        results[1].1 / results[0].1
    );
    Ok(())
}

/// Times `LwrDriver::handle` + reply encoding on measurements recorded from the simulator in command
/// mode (moving arm, every field filled).
fn run_driver(calls: usize, reps: usize) -> anyhow::Result<()> {
    use softcontact_nodes::lwr_driver::{LwrDriver, Params as DriverParams};
    use softcontact_sim::{SimConfig, Simulator};
    use softcontact_wire::fri::{self, Quality, flags};
    if calls == 0 || reps == 0 {
        bail!("--calls and --reps must be positive");
    }
    let mut sim = Simulator::new(SimConfig::above_surface(softcontact_sim::sponge(), 1))?;
    let mut cmd = fri::Command::default();
    cmd.krl.int[0] = 30;
    cmd.flags = flags::JOINT_IMPEDANCE;
    let mut datagrams = Vec::new();
    for i in 0..1500u16 {
        let m = sim.measurement();
        cmd.header.refl_seq = m.header.send_seq;
        cmd.krl.int[1] = i32::from(m.intf.quality == Quality::Perfect);
        cmd.jnt_pos = m.data.msr_jnt_pos;
        cmd.add_jnt_trq = [0.0, -2.0, 0.0, 1.0, 0.0, 0.3, 0.05];
        sim.command(&cmd);
        sim.step_cycle()?;
        if i >= 500 {
            datagrams.push(m.encode());
        }
    }
    let mut driver = LwrDriver::new(DriverParams::default());
    let torque = [0.0, -40.0, 0.0, 12.0, 0.0, 1.0, 0.0];
    let ns = best_ns(calls, reps, |i| {
        if i % 2 == 0 {
            driver.set_command(&torque).ok();
        }
        if let Ok((reply, out)) = driver.handle(&datagrams[i % datagrams.len()]) {
            black_box(reply.encode());
            black_box(driver.tool_motion(&out.q, &out.dq).twist[0]);
        }
    });
    println!("FRI driver per cycle (decode, reply, tool pose and twist, encode): {ns:.0} ns (goal ≤ 20 µs)");
    Ok(())
}

/// Pushes a simulated sponge with a steady additional torque through the whole FRI/RDT exchange.
fn run_sim(seconds: f64, reps: usize) -> anyhow::Result<()> {
    use softcontact_sim::{SimConfig, Simulator};
    use softcontact_wire::fri::{self, Quality, flags};
    if !(seconds.is_finite() && seconds > 0.0 && reps > 0) {
        bail!("--seconds and --reps must be positive");
    }
    let sponge = softcontact_contact::ContactModel::new(Kind::AzadFeatherstone, 25_044.0, 1100.0)?;
    let cycles = (seconds * 1000.0).round() as usize;
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        let mut sim = Simulator::new(SimConfig::above_surface(sponge.clone(), 1))?;
        let mut cmd = fri::Command::default();
        cmd.krl.int[0] = 30;
        cmd.flags = flags::JOINT_IMPEDANCE;
        cmd.jnt_damping = [0.7; 7];
        let start = Instant::now();
        for i in 0..cycles {
            let m = fri::Measurement::decode(&sim.measurement().encode())?;
            cmd.header.send_seq = i as u16;
            cmd.header.refl_seq = m.header.send_seq;
            cmd.krl.int[1] = i32::from(m.intf.quality == Quality::Perfect);
            cmd.jnt_pos = m.data.msr_jnt_pos;
            // A gentle push down through A2 and A3 once commanding.
            cmd.add_jnt_trq = [0.0, -3.0, 0.0, 2.0, 0.0, 0.5, 0.0];
            sim.command(&fri::Command::decode(&cmd.encode())?);
            sim.step_cycle()?;
            black_box(sim.ft_record().encode());
        }
        best = best.min(start.elapsed().as_secs_f64());
    }
    let factor = seconds / best;
    println!("simulated {seconds} s (arm + KRC + sponge + F/T, 1 kHz FRI cycle, 1 ms steps) in {:.3} s wall", best);
    println!("real-time factor {factor:.0}× (goal ≥ 1000×); {:.2} µs per 1 ms cycle", best / cycles as f64 * 1e6);
    Ok(())
}

/// Samples of a sponge-like surface (Azad-Featherstone, 280 N at 5 cm) pushed at 1 Hz, 0.2 N noise.
fn sponge_samples(n: usize) -> Vec<Sample> {
    let mut rng = SmallRng::seed_from_u64(9);
    let (k, l) = (280.0 / 0.05f64.powf(1.5), 1100.0);
    let w = 2.0 * std::f64::consts::PI;
    (0..n)
        .map(|i| {
            let t = i as f64 * 0.01;
            let (z, zd) = (0.026 + 0.024 * (w * t).sin(), 0.024 * w * (w * t).cos());
            Sample { z, zdot: zd, f: k * z.powf(1.5) + l * z.sqrt() * zd + rng.random_range(-0.35..0.35) }
        })
        .collect()
}

fn run_contact(window: usize, reps: usize, json: Option<PathBuf>) -> anyhow::Result<()> {
    if reps == 0 {
        bail!("--reps must be positive");
    }
    let cfg = FitConfig::default();
    let stream = sponge_samples(window + 10_000);
    let mut estimator = WindowEstimator::new(window, cfg)?;
    for s in &stream[..window] {
        estimator.push(*s)?;
    }
    let pushes = 1_000_000;
    let extra = &stream[window..];
    let push_ns = best_ns(pushes, reps, |i| {
        black_box(estimator.push(extra[i % extra.len()])).ok();
    });
    let refit_calls = 2000;
    let refit_ns = best_ns(refit_calls, reps, |_| {
        black_box(estimator.refit().map(|e| e.selected).ok());
    });
    let samples: Vec<Sample> = estimator.samples().copied().collect();
    let exponent_ns = best_ns(50, reps, |_| {
        black_box(
            estimate_exponent(&samples, DampingExponent::Fixed(0.5), 1.0, (0.8, 2.5), &cfg).map(|f| f.exponents.a).ok(),
        );
    });
    let offset_ns = best_ns(20, reps, |_| {
        let e = Kind::AzadFeatherstone.exponents().expect("named kind");
        black_box(estimate_contact_offset(&samples, e, (-0.02, 0.02), None, &cfg).map(|(d, _)| d).ok());
    });
    let rows = [
        ("sliding update per sample", push_ns, 200.0),
        ("refit, all kinds, 5-fold CV", refit_ns, 100_000.0),
        ("exponent estimation", exponent_ns, 1_000_000.0),
        ("contact offset estimation", offset_ns, f64::NAN),
    ];
    println!("contact estimation over a window of {window} samples");
    println!("{:<30} {:>14} {:>14}", "term", "ns", "goal [ns]");
    for (name, ns, goal) in rows {
        println!("{name:<30} {ns:>14.1} {:>14}", if goal.is_nan() { "-".to_string() } else { format!("≤ {goal}") });
    }
    if let Some(path) = json {
        let v: Vec<_> = rows.iter().map(|(n, ns, g)| serde_json::json!({"term": n, "ns": ns, "goal_ns": if g.is_nan() { None } else { Some(g) }})).collect();
        std::fs::write(&path, serde_json::to_string_pretty(&serde_json::json!({"window": window, "terms": v}))?)?;
    }
    Ok(())
}

fn run_dynamics(calls: usize, reps: usize, pinocchio: bool, json: Option<PathBuf>) -> anyhow::Result<()> {
    if calls == 0 || reps == 0 {
        bail!("--calls and --reps must be positive");
    }
    let model = lwr4::model();
    eprintln!("timing softcontact-dynamics on the LWR IV ({calls} calls × {reps} repetitions per term)");
    let ours = time_ours(&model, calls, reps)?;
    let reference = if pinocchio { Some(time_pinocchio(calls, reps)?) } else { None };

    println!("{:<18} {:>10} {:>12} {:>8} {:>6}  Pinocchio term", "term", "ours [ns]", "Pinocchio", "ratio", "goal");
    let mut rows = Vec::new();
    for ((name, pin_name, goal), ours_ns) in TERMS.iter().zip(&ours) {
        let pin_ns = reference.as_ref().and_then(|r| r[name].as_f64());
        let ratio = pin_ns.map(|p| ours_ns / p);
        let verdict = match (ratio, goal) {
            (Some(r), Some(g)) => format!("{}{g}", if r <= *g { "≤" } else { "✗>" }),
            (_, Some(g)) => format!("≤{g}"),
            _ => String::new(),
        };
        println!(
            "{name:<18} {ours_ns:>10.1} {:>12} {:>8} {verdict:>6}  {pin_name}",
            pin_ns.map(|p| format!("{p:.1}")).unwrap_or_else(|| "-".into()),
            ratio.map(|r| format!("{r:.2}")).unwrap_or_else(|| "-".into())
        );
        rows.push(
            serde_json::json!({"term": name, "ours_ns": ours_ns, "pinocchio_ns": pin_ns, "ratio": ratio, "goal": goal}),
        );
    }
    if let Some(path) = json {
        std::fs::write(
            &path,
            serde_json::to_string_pretty(&serde_json::json!({"calls": calls, "reps": reps, "terms": rows}))?,
        )?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
