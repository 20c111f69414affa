//! `softcontact demo --graph`: the same experiments with the real node processes over DDS in real
//! time. Each surface gets its own graph (`launch-scripts/sim.sh --isolated --surface lab_NAME`, in a
//! network namespace with only loopback); this binary runs inside it as the client, like a user at the
//! robot: it records the run with `softcontact record`, pushes the surface at 1 Hz with force commands
//! (the graph's controller takes force commands only, so identification is force-driven here, not the
//! position-driven sine of the in-process run), reads the estimator's model and fitness table, has the
//! controller retreat and re-tare the sensor (/deformation_controller/retare), then
//! sends the force commands and reads the force at the end of each move: the simulator's true contact
//! force (/sim_arm/contact_wrench) for the grade, the sensor's reading (the controller's state) beside it.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use std::collections::VecDeque;

use anyhow::Context;
use nalgebra::Vector3;
use ros2_client::{Name, ServiceTypeName};
use softcontact_msgs::geometry_msgs::WrenchStamped;
use softcontact_msgs::softcontact_msgs::{ContactModel, ControllerState, ForceCommand};
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use softcontact_nodes::geometry::ContactGeometry;
use softcontact_nodes::{deformation_controller, ros};

use super::experiment::{CommandResult, Plan, SurfaceSpec};
use super::report::{Fitness, Identified, Report, SurfaceReport};

fn client_report(out: &Path, name: &str) -> PathBuf {
    out.join(format!("graph_{name}.json"))
}

/// Runs one graph per surface, one after the other, and collects what the clients measured.
pub fn run(specs: &[SurfaceSpec], plan: Plan, out: &Path) -> anyhow::Result<Report> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().context("the repository root")?;
    let script = root.join("launch-scripts/sim.sh");
    anyhow::ensure!(script.exists(), "--graph needs the repository's {} (run from a checkout)", script.display());
    let exe = std::env::current_exe()?;
    let mut surfaces = Vec::new();
    for spec in specs {
        let logs = out.join("graph_logs").join(spec.name);
        let _ = std::fs::remove_file(client_report(out, spec.name));
        println!("{}: starting the graph (logs in {}) …", spec.name, logs.display());
        // The controller's limits of the in-process run, as a parameter overlay.
        std::fs::create_dir_all(&logs)?;
        let limits = logs.join("demo_limits.yaml");
        std::fs::write(
            &limits,
            format!(
                "deformation_controller:\n  ros__parameters:\n    max_force: {:?}\n    max_deformation: {:?}\n    \
                 force_limit: {:?}\n",
                spec.max_force,
                spec.max_deformation,
                1.2 * spec.max_force
            ),
        )?;
        let mut cmd = Command::new(&script);
        cmd.args(["--isolated", "--surface", &format!("lab_{}", spec.name), "--params-file"])
            .arg(&limits)
            .arg("--log-dir")
            .arg(&logs)
            .arg("--run")
            .arg(&exe)
            .args(["demo", "--graph-client", spec.name, "--out"])
            .arg(out)
            .args(["--runs", &plan.identification_runs.to_string(), "--commands", &plan.commands.to_string()]);
        // The node binaries beside this one, if they are built; else launch.sh builds them.
        if let Some(dir) = exe.parent().filter(|d| d.join("sim_arm").exists()) {
            cmd.env("SOFTCONTACT_BIN", dir);
        }
        let status = cmd.status().with_context(|| format!("running {}", script.display()))?;
        anyhow::ensure!(status.success(), "{}: the graph run failed (logs in {})", spec.name, logs.display());
        let path = client_report(out, spec.name);
        let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        surfaces.push(serde_json::from_str(&text).with_context(|| path.display().to_string())?);
    }
    Ok(Report { simulation: true, mode: "graph".into(), surfaces, arm: None })
}

/// `softcontact record` beside the client: stopped with SIGINT (as Ctrl-C) at the end, or when the
/// client fails, so that it never outlives the graph.
struct Recorder(Option<std::process::Child>);

impl Recorder {
    /// Whether it stopped cleanly.
    fn stop(&mut self) -> std::io::Result<bool> {
        let Some(mut child) = self.0.take() else { return Ok(true) };
        let signalled = Command::new("kill").args(["-INT", &child.id().to_string()]).status()?.success();
        Ok(signalled && child.wait()?.success())
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// What the client has heard from the graph.
struct Heard {
    state: Option<ControllerState>,
    model: Option<ContactModel>,
    /// The last few normal forces of the controller's 100 Hz state (the sensor's reading).
    recent: Vec<f64>,
    /// The last 10 ms of the simulator's true normal force (/sim_arm/contact_wrench, 1 kHz).
    recent_true: std::collections::VecDeque<f64>,
    max_force: f64,
}

fn mean<'a>(v: impl ExactSizeIterator<Item = &'a f64>) -> f64 {
    let n = v.len().max(1) as f64;
    v.sum::<f64>() / n
}

/// Inside the namespace, with the graph up: the experiments on one surface.
pub fn client(spec: &SurfaceSpec, plan: Plan, out: &Path) -> anyhow::Result<()> {
    let exe = std::env::current_exe()?;
    let recording = out.join(format!("{}_graph.mcap", spec.name));
    let _ = std::fs::remove_file(&recording);
    let mut recorder =
        Recorder(Some(Command::new(&exe).arg("record").arg("-o").arg(&recording).stdout(Stdio::null()).spawn()?));
    let mut node = ros::node("softcontact_demo")?;
    let states = ros::subscription::<ControllerState>(&mut node, "/deformation_controller/state", ros::sensor_qos())?;
    let models = ros::subscription::<ContactModel>(&mut node, "/contact_estimator/model", ros::reliable_qos())?;
    let truth = ros::subscription::<WrenchStamped>(&mut node, "/sim_arm/contact_wrench", ros::sensor_qos())?;
    let retare = node.create_client::<TriggerRequest, TriggerResponse>(
        ros::service_mapping("cyclone")?,
        &Name::new("/deformation_controller", "retare")?,
        &ServiceTypeName::new("std_srvs", "Trigger"),
        ros::reliable_qos(),
        ros::reliable_qos(),
    )?;
    let commands =
        ros::publisher::<ForceCommand>(&mut node, "/deformation_controller/force_command", ros::reliable_qos())?;
    // The true normal force along the controller's normal (its default: the graph's parameters).
    let geometry = ContactGeometry::lwr4(Vector3::from(deformation_controller::Params::default().normal))
        .context("the controller's normal")?;
    let mut heard =
        Heard { state: None, model: None, recent: Vec::new(), recent_true: VecDeque::new(), max_force: 0.0 };
    let listen = |heard: &mut Heard, seconds: f64| -> anyhow::Result<()> {
        let until = Instant::now() + Duration::from_secs_f64(seconds);
        loop {
            while let Ok(Some((m, _))) = models.take() {
                heard.model = Some(m);
            }
            while let Ok(Some((w, _))) = truth.take() {
                let f = w.wrench.force;
                heard.recent_true.push_back(geometry.normal_force(&Vector3::new(f.x, f.y, f.z)));
                if heard.recent_true.len() > 10 {
                    heard.recent_true.pop_front();
                }
            }
            while let Ok(Some((s, _))) = states.take() {
                heard.max_force = heard.max_force.max(s.f);
                heard.recent.push(s.f);
                if heard.recent.len() > 3 {
                    heard.recent.remove(0);
                }
                anyhow::ensure!(!s.contact_lost, "contact lost");
                heard.state = Some(s);
            }
            if Instant::now() >= until {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    };

    let start = Instant::now();
    while !heard.state.as_ref().is_some_and(|s| s.in_contact) {
        anyhow::ensure!(start.elapsed() < Duration::from_secs(30), "no contact after 30 s");
        listen(&mut heard, 0.05)?;
    }
    listen(&mut heard, 0.3)?; // the controller's reader matches our writer
    eprintln!("{}: contact after {:.1} s; identification pushes at 1 Hz", spec.name, start.elapsed().as_secs_f64());
    let (high, low) = spec.push_forces;
    for _ in 0..plan.identification_runs * plan.push_periods as usize {
        for force in [high, low] {
            commands.publish(ForceCommand { force, duration: 0.5 })?;
            listen(&mut heard, 0.5)?;
        }
    }
    listen(&mut heard, 1.1)?; // one more refit
    let model = heard.model.clone().context("the estimator published no model")?;
    // As on the robot (and in-process): the sensor re-tared with the hand free before the control run.
    let request = retare.send_request(TriggerRequest::default()).map_err(|e| anyhow::anyhow!("re-tare: {e:?}"))?;
    let asked = Instant::now();
    let response = loop {
        if let Ok(Some((id, r))) = retare.receive_response()
            && id == request
        {
            break r;
        }
        anyhow::ensure!(asked.elapsed() < Duration::from_secs(10), "no answer to the re-tare in 10 s");
        listen(&mut heard, 0.01)?;
    };
    anyhow::ensure!(response.success, "re-tare: {}", response.message);
    let mut approached = false;
    while !(approached && heard.state.as_ref().is_some_and(|s| s.in_contact)) {
        anyhow::ensure!(asked.elapsed() < Duration::from_secs(20), "no contact again after the re-tare");
        approached |= heard.state.as_ref().is_some_and(|s| !s.in_contact);
        listen(&mut heard, 0.01)?;
    }
    listen(&mut heard, 0.5)?;
    eprintln!("{}: {}", spec.name, response.message);
    let max_force = heard.max_force;
    eprintln!(
        "{}: estimator chose {} (k {:.0}); maximum force {max_force:.1} N",
        spec.name, model.kind, model.stiffness
    );

    let mut results = Vec::new();
    for i in 0..plan.commands {
        let (_, _, command) = CommandResult::planned(i, max_force);
        let stiffness = heard.model.as_ref().map_or(f64::NAN, |m| m.stiffness);
        commands.publish(ForceCommand { force: command, duration: plan.move_duration })?;
        listen(&mut heard, plan.move_duration)?;
        anyhow::ensure!(!heard.recent_true.is_empty(), "no true contact force from /sim_arm/contact_wrench");
        let (reached, measured) = (mean(heard.recent_true.iter()), mean(heard.recent.iter()));
        eprintln!("{}: command {command:.2} N, reached {reached:.2} N (the sensor read {measured:.2} N)", spec.name);
        results.push(CommandResult::new(i, max_force, reached, measured, stiffness));
    }
    anyhow::ensure!(recorder.stop()?, "the recorder did not stop cleanly");

    let p = &model.contact_position;
    let report = SurfaceReport {
        name: spec.name.into(),
        fitness: model
            .candidate_kinds
            .iter()
            .zip(model.candidate_fitness_mean.iter().zip(&model.candidate_fitness_std))
            .map(|(k, (m, s))| (k.clone(), Fitness { mean: *m, std: *s }))
            .collect(),
        selected: model.kind.clone(),
        identified: Identified {
            kind: model.kind.clone(),
            stiffness: model.stiffness,
            damping: model.damping,
            exponents: softcontact_contact::Exponents { a: model.exponent_a, b: model.exponent_b, c: model.exponent_c },
            contact_position: [p.x, p.y, p.z],
            samples: (model.window_fill * 1200.0).round() as usize,
        },
        max_force,
        commands: results,
        simulated_surface: spec.truth.clone(),
        discrepancy: None,
    };
    let path = client_report(out, spec.name);
    std::fs::write(&path, serde_json::to_string_pretty(&report)?).with_context(|| path.display().to_string())?;
    Ok(())
}
