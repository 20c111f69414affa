//! `softcontact demo --graph`: the same experiments with the real node processes over DDS in real
//! time. Each surface gets its own graph (`launch-scripts/sim.sh --isolated --surface lab_NAME`, in a
//! network namespace with only loopback); this binary runs inside it as the client, like a user at the
//! robot: it records the run with `softcontact record`, pushes the surface at 1 Hz with force commands
//! (the graph's controller takes force commands only, so identification is force-driven here, not the
//! position-driven sine of the in-process run), reads the estimator's model and fitness table, has the
//! controller retreat and re-tare the sensor (/deformation_controller/retare), then
//! sends the force commands and reads the force at the end of each move: the simulator's true contact
//! force (/sim_arm/contact_wrench) for the grade, the sensor's reading (the controller's state) beside it.
//! Then, as a user would: `softcontact discrepancy` on that recording, and a second graph started with
//! the parameter overlay it writes, for the force commands again through the augmented model.

use softcontact_msgs::topics;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use std::collections::VecDeque;

use anyhow::Context;
use nalgebra::Vector3;
use softcontact_msgs::geometry_msgs::WrenchStamped;
use softcontact_msgs::softcontact_msgs::{ContactModel, ContactState, ControllerState, ForceCommand};
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use softcontact_nodes::deformation_controller;
use softcontact_nodes::geometry::ContactGeometry;
use softcontact_nodes::runtime::ros;

use super::experiment::{CommandResult, ModelUse, Plan, SurfaceSpec};
use super::report::{Discrepancy, Fitness, Identified, Report, SurfaceReport};

fn client_report(out: &Path, name: &str) -> PathBuf {
    out.join(format!("graph_{name}.json"))
}

/// The client's report of the control experiment through the augmented model.
fn augmented_report(out: &Path, name: &str) -> PathBuf {
    out.join(format!("graph_{name}_augmented.json"))
}

/// Runs one graph per surface, one after the other, and collects what the clients measured. With
/// `plan.augmented`, the discrepancy workflow then runs on the first graph's recording, and a second
/// graph, started with the augmented model's parameter overlay as a user would start it, runs the
/// control experiment again through it.
/// `secure`: each graph under ROS 2 security (`sim.sh --secure`), the client in `/user`'s enclave.
pub fn run(specs: &[SurfaceSpec], plan: Plan, out: &Path, secure: bool) -> anyhow::Result<Report> {
    let mut surfaces = Vec::new();
    for spec in specs {
        let logs = out.join("graph_logs").join(spec.name);
        std::fs::create_dir_all(&logs)?;
        // The controller's limits of the in-process run, as a parameter overlay.
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
        let report_path = client_report(out, spec.name);
        let _ = std::fs::remove_file(&report_path);
        println!("{}: starting the graph (logs in {}) …", spec.name, logs.display());
        launch(spec, plan, out, &logs, &[&limits], &["--graph-client", spec.name], secure)?;
        let text =
            std::fs::read_to_string(&report_path).with_context(|| format!("reading {}", report_path.display()))?;
        let mut report: SurfaceReport =
            serde_json::from_str(&text).with_context(|| report_path.display().to_string())?;
        if plan.augmented {
            let (discrepancy, overlay) = augment(out, spec.name, &logs)?;
            let path = augmented_report(out, spec.name);
            let _ = std::fs::remove_file(&path);
            println!("{}: the graph again, with {} …", spec.name, overlay.display());
            let max_force = format!("{:?}", report.max_force);
            let args = ["--graph-client", spec.name, "--graph-augmented", &max_force];
            launch(spec, plan, out, &logs.join("augmented"), &[&limits, &overlay], &args, secure)?;
            let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
            let mut commands: Vec<CommandResult> =
                serde_json::from_str(&text).with_context(|| path.display().to_string())?;
            for c in commands.iter_mut().filter(|c| c.model_stiffness.is_nan()) {
                // Before the estimator's first model: the controller's initial model, the augmented one.
                c.model_stiffness = discrepancy.augmented_model.stiffness;
            }
            report.commands.extend(commands);
            report.discrepancy = Some(discrepancy);
        }
        surfaces.push(report);
    }
    Ok(Report { simulation: true, mode: "graph".into(), surfaces, arm: None })
}

/// One graph of the surface `spec` (`launch-scripts/sim.sh --isolated`, logs in `logs`, the parameter
/// `overlays` on top of config/), with this binary inside as `demo CLIENT_ARGS`; `secure`: `sim.sh --secure`,
/// the client in `/user`'s enclave.
fn launch(
    spec: &SurfaceSpec,
    plan: Plan,
    out: &Path,
    logs: &Path,
    overlays: &[&Path],
    client_args: &[&str],
    secure: bool,
) -> anyhow::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().context("the repository root")?;
    let script = root.join("launch-scripts/sim.sh");
    anyhow::ensure!(script.exists(), "--graph needs the repository's {} (run from a checkout)", script.display());
    let exe = std::env::current_exe()?;
    std::fs::create_dir_all(logs)?;
    let mut cmd = Command::new(&script);
    cmd.args(["--isolated", "--surface", &format!("lab_{}", spec.name)]);
    for overlay in overlays {
        cmd.arg("--params-file").arg(overlay);
    }
    let client_args = if secure {
        cmd.arg("--secure");
        [client_args, &["--enclave", "/user"]].concat()
    } else {
        client_args.to_vec()
    };
    cmd.arg("--log-dir").arg(logs).arg("--run").arg(&exe).arg("demo").args(client_args).arg("--out").arg(out).args([
        "--runs",
        &plan.identification_runs.to_string(),
        "--commands",
        &plan.commands.to_string(),
    ]);
    // The node binaries beside this one, if they are built; else launch.sh builds them.
    if let Some(dir) = exe.parent().filter(|d| d.join("sim_arm").exists()) {
        cmd.env("SOFTCONTACT_BIN", dir);
    }
    let status = cmd.status().with_context(|| format!("running {}", script.display()))?;
    anyhow::ensure!(status.success(), "{}: the graph run failed (logs in {})", spec.name, logs.display());
    Ok(())
}

/// The discrepancy workflow on the first graph's recording, as `softcontact discrepancy FILE --out DIR`
/// runs it: what it names, and the parameter overlay of the augmented model.
fn augment(out: &Path, name: &str, logs: &Path) -> anyhow::Result<(Discrepancy, PathBuf)> {
    let file = out.join(format!("{name}_graph.mcap"));
    let normal = deformation_controller::Params::default().normal;
    let args = crate::discrepancy_cmd::DiscrepancyArgs {
        recording: crate::identify_cmd::IdentifyArgs {
            file,
            json: None,
            normal: normal.to_vec(),
            onset: None,
            sample_period: Some(0.01),
        },
        model: None,
        surface: None,
        out: logs.to_path_buf(),
        loading_paths: false,
        arm: false,
        closed_loop: false,
    };
    let analysis =
        crate::discrepancy_cmd::analyse_file(&args, false).with_context(|| format!("{name}: discrepancy"))?;
    let report = &analysis.report;
    let surface = analysis.surface + report.contact_shift * Vector3::from(normal).normalize();
    let overlay = crate::discrepancy_cmd::write_overlay(logs, name, &report.model, &surface)?;
    Ok((Discrepancy::of(report), overlay))
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
    /// A state of the estimator's has arrived: it pairs readings, and it has seen free space (joined while
    /// the hand presses, it publishes nothing until the hand has left the surface).
    estimator_heard: bool,
    /// The last few normal forces of the controller's 100 Hz state (the sensor's reading).
    recent: Vec<f64>,
    /// The last 10 ms of the simulator's true normal force (/sim_arm/contact_wrench, 1 kHz).
    recent_true: VecDeque<f64>,
    max_force: f64,
}

fn mean<'a>(v: impl ExactSizeIterator<Item = &'a f64>) -> f64 {
    let n = v.len().max(1) as f64;
    v.sum::<f64>() / n
}

/// The demo's node in the graph: what it hears and the force commands it sends.
struct Client {
    node: ros2_client::Node,
    states: ros2_client::Subscription<ControllerState>,
    estimator_states: ros2_client::Subscription<ContactState>,
    models: ros2_client::Subscription<ContactModel>,
    truth: ros2_client::Subscription<WrenchStamped>,
    commands: ros2_client::Publisher<ForceCommand>,
    /// The true normal force along the controller's normal (its default: the graph's parameters).
    geometry: ContactGeometry,
    heard: Heard,
}

impl Client {
    fn new(enclave: Option<&str>) -> anyhow::Result<Self> {
        let mut node = ros::tool_node("softcontact_demo", "/", enclave)?;
        let states = ros::subscription(&mut node, &topics::CONTROLLER_STATE, ros::sensor_qos())?;
        let estimator_states = ros::subscription(&mut node, &topics::CONTACT_STATE, ros::sensor_qos())?;
        let models = ros::subscription(&mut node, &topics::CONTACT_MODEL, ros::reliable_qos())?;
        let truth = ros::subscription(&mut node, &topics::CONTACT_WRENCH, ros::sensor_qos())?;
        let commands = ros::publisher(&mut node, &topics::FORCE_COMMAND, ros::reliable_qos())?;
        let geometry = ContactGeometry::lwr4(Vector3::from(deformation_controller::Params::default().normal))
            .context("the controller's normal")?;
        let heard = Heard {
            state: None,
            model: None,
            estimator_heard: false,
            recent: Vec::new(),
            recent_true: VecDeque::new(),
            max_force: 0.0,
        };
        Ok(Self { node, states, estimator_states, models, truth, commands, geometry, heard })
    }

    /// Takes what arrives for `seconds`.
    fn listen(&mut self, seconds: f64) -> anyhow::Result<()> {
        let heard = &mut self.heard;
        let until = Instant::now() + Duration::from_secs_f64(seconds);
        loop {
            while let Ok(Some((m, _))) = self.models.take() {
                heard.model = Some(m);
            }
            while let Ok(Some(_)) = self.estimator_states.take() {
                heard.estimator_heard = true;
            }
            while let Ok(Some((w, _))) = self.truth.take() {
                let f = w.wrench.force;
                heard.recent_true.push_back(self.geometry.normal_force(&Vector3::new(f.x, f.y, f.z)));
                if heard.recent_true.len() > 10 {
                    heard.recent_true.pop_front();
                }
            }
            while let Ok(Some((s, _))) = self.states.take() {
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
    }

    fn in_contact(&self) -> bool {
        self.heard.state.as_ref().is_some_and(|s| s.in_contact)
    }

    /// Until the controller reports contact (at most 30 s), and a little longer, so that its reader
    /// matches our writer.
    fn wait_for_contact(&mut self, name: &str) -> anyhow::Result<()> {
        let start = Instant::now();
        while !self.in_contact() {
            anyhow::ensure!(start.elapsed() < Duration::from_secs(30), "no contact after 30 s");
            self.listen(0.05)?;
        }
        self.listen(0.3)?;
        eprintln!("{name}: contact after {:.1} s", start.elapsed().as_secs_f64());
        Ok(())
    }

    /// Whether a state of the estimator's arrives within `seconds`.
    fn estimator_heard(&mut self, seconds: f64) -> anyhow::Result<bool> {
        let start = Instant::now();
        while !self.heard.estimator_heard && start.elapsed().as_secs_f64() < seconds {
            self.listen(0.05)?;
        }
        Ok(self.heard.estimator_heard)
    }

    /// Has the controller re-tare the sensor (it lifts the hand clear, tares and approaches again) and
    /// waits until the hand is back in contact; the controller's answer.
    fn retare_and_touch_again(
        &mut self,
        retare: &ros2_client::service::Client<TriggerRequest, TriggerResponse>,
    ) -> anyhow::Result<String> {
        let request = retare.send_request(TriggerRequest::default()).map_err(|e| anyhow::anyhow!("re-tare: {e:?}"))?;
        let asked = Instant::now();
        let response = loop {
            if let Ok(Some((id, r))) = retare.receive_response()
                && id == request
            {
                break r;
            }
            anyhow::ensure!(asked.elapsed() < Duration::from_secs(10), "no answer to the re-tare in 10 s");
            self.listen(0.01)?;
        };
        anyhow::ensure!(response.success, "re-tare: {}", response.message);
        let mut approached = false;
        while !(approached && self.in_contact()) {
            anyhow::ensure!(asked.elapsed() < Duration::from_secs(20), "no contact again after the re-tare");
            approached |= !self.in_contact();
            self.listen(0.01)?;
        }
        self.listen(0.5)?;
        Ok(response.message)
    }

    /// The force-control paper's force commands, ratios of `max_force`, each graded at the end of its move on the true
    /// force, with the sensor's reading beside it.
    fn control(
        &mut self,
        name: &str,
        plan: Plan,
        max_force: f64,
        model: ModelUse,
    ) -> anyhow::Result<Vec<CommandResult>> {
        let mut results = Vec::new();
        for i in 0..plan.commands {
            let (_, _, command) = CommandResult::planned(i, max_force);
            let stiffness = self.heard.model.as_ref().map_or(f64::NAN, |m| m.stiffness);
            self.commands.publish(ForceCommand { force: command, duration: plan.move_duration })?;
            self.listen(plan.move_duration)?;
            let heard = &self.heard;
            anyhow::ensure!(!heard.recent_true.is_empty(), "no true contact force from /sim_arm/contact_wrench");
            let (reached, measured) = (mean(heard.recent_true.iter()), mean(heard.recent.iter()));
            eprintln!("{name}: command {command:.2} N, reached {reached:.2} N (the sensor read {measured:.2} N)");
            results.push(CommandResult { model, ..CommandResult::new(i, max_force, reached, measured, stiffness) });
        }
        Ok(results)
    }
}

/// Inside the namespace, with the graph up: the experiments on one surface.
/// `enclave`: the client's and its recorder's on a secure graph.
pub fn client(spec: &SurfaceSpec, plan: Plan, out: &Path, enclave: Option<&str>) -> anyhow::Result<()> {
    let exe = std::env::current_exe()?;
    let recording = out.join(format!("{}_graph.mcap", spec.name));
    let _ = std::fs::remove_file(&recording);
    let mut recorder = Recorder(Some(
        Command::new(&exe)
            .arg("record")
            .args(enclave.map(|e| ["--enclave", e]).into_iter().flatten())
            .arg("-o")
            .arg(&recording)
            .stdout(Stdio::null())
            .spawn()?,
    ));
    let mut c = Client::new(enclave)?;
    let retare_name = ros::resolve(&c.node, softcontact_msgs::topics::RETARE_SERVICE)?;
    let retare = ros::trigger_client(&mut c.node, ros::service_mapping("cyclone")?, &retare_name)?;
    c.wait_for_contact(spec.name)?;
    // The pushes start once the estimator is heard. One that joined after the hand touched (a secure
    // graph's handshakes take seconds) and while it presses stays silent, with no onset: the hand leaves
    // the surface and touches it again.
    if !c.estimator_heard(5.0)? {
        eprintln!("{}: no state from the estimator: the hand leaves the surface and touches it again", spec.name);
        let message = c.retare_and_touch_again(&retare)?;
        eprintln!("{}: {message}", spec.name);
        anyhow::ensure!(c.estimator_heard(5.0)?, "no state from the estimator after the second touch");
    }
    eprintln!("{}: identification pushes at 1 Hz", spec.name);
    let (high, low) = spec.push_forces;
    for _ in 0..plan.identification_runs * plan.push_periods as usize {
        for force in [high, low] {
            c.commands.publish(ForceCommand { force, duration: 0.5 })?;
            c.listen(0.5)?;
        }
    }
    c.listen(1.1)?; // one more refit
    let model = c.heard.model.clone().context("the estimator published no model")?;
    // As on the robot (and in-process): the sensor re-tared with the hand free before the control run.
    let message = c.retare_and_touch_again(&retare)?;
    eprintln!("{}: {message}", spec.name);
    let max_force = c.heard.max_force;
    eprintln!(
        "{}: estimator chose {} (k {:.0}); maximum force {max_force:.1} N",
        spec.name, model.kind, model.stiffness
    );

    let results = c.control(spec.name, plan, max_force, ModelUse::Identified)?;
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

/// Inside the namespace of the second graph (its controller starting from the augmented model, its
/// estimator carrying the model's effects): the control experiment again, planned from the first
/// graph's `max_force`.
pub fn client_augmented(
    spec: &SurfaceSpec,
    plan: Plan,
    max_force: f64,
    out: &Path,
    enclave: Option<&str>,
) -> anyhow::Result<()> {
    anyhow::ensure!(max_force.is_finite() && max_force > 0.0, "the maximum force must be positive");
    let mut c = Client::new(enclave)?;
    c.wait_for_contact(spec.name)?;
    c.listen(0.5)?;
    let results = c.control(spec.name, plan, max_force, ModelUse::Augmented)?;
    let path = augmented_report(out, spec.name);
    std::fs::write(&path, serde_json::to_string_pretty(&results)?).with_context(|| path.display().to_string())?;
    Ok(())
}
