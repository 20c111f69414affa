//! `softcontact demo` in-process, in full (the force-control paper's 10 identification runs and 30 commands per
//! surface): the paper's model choices, the goals of the control experiment (cycle 1 within 10 % of
//! the command, cycles 2–5 within 2 %), the online update doing real work on surfaces whose effects no
//! model kind has; the discrepancy workflow naming those effects from the identification runs and the
//! control experiment again through the augmented model (every command within 1 %); and the files it
//! promises (tables as JSON, a recording per surface, five figures).

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use softcontact_msgs::softcontact_msgs::ForceCommand;

const RATIOS: [[f64; 6]; 2] = [[0.8, 0.4, 0.7, 0.3, 0.5, 0.6], [0.75, 0.35, 0.65, 0.25, 0.45, 0.55]];

#[test]
fn the_demo_reproduces_seed_001_and_beats_its_numbers() {
    let out = std::env::temp_dir().join(format!("softcontact-demo-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let json = out.join("demo.json");
    let run = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["demo", "--out"])
        .arg(&out)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&run.stdout);
    eprintln!("{text}{}", String::from_utf8_lossy(&run.stderr));
    assert!(run.status.success(), "the demo ran");
    for heading in ["TABLE I", "TABLE II", "TABLE III", "viscoelastic relaxation", "hysteresis", "drift"] {
        assert!(text.contains(heading), "the output says {heading}");
    }
    assert!(text.contains("simulation") && text.contains("paper"), "comparisons are labelled");

    let report: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let surfaces = report["surfaces"].as_array().unwrap();
    assert_eq!(surfaces.len(), 2);
    for (s, (name, kind)) in surfaces.iter().zip([("sponge", "azad_featherstone"), ("dice", "kelvin_voigt")]) {
        assert_eq!(s["name"], name);
        // The force-control paper's choices, made from the fitness table itself.
        let fitness = s["fitness"].as_object().unwrap();
        assert_eq!(fitness.len(), 3, "{name}: three kinds fitted");
        let best =
            fitness.iter().max_by(|a, b| a.1["mean"].as_f64().unwrap().total_cmp(&b.1["mean"].as_f64().unwrap()));
        assert_eq!(best.unwrap().0, kind, "{name}: best fitness");
        assert_eq!(s["selected"], kind, "{name}: chosen as the force-control paper chose");
        for f in fitness.values() {
            let (m, sd) = (f["mean"].as_f64().unwrap(), f["std"].as_f64().unwrap());
            assert!(m > 0.5 && m <= 1.0 && (0.0..0.1).contains(&sd), "{name}: fitness {m} ± {sd}");
        }

        let max_force = s["max_force"].as_f64().unwrap();
        let all = s["commands"].as_array().unwrap();
        assert_eq!(all.len(), 60, "{name}: both control experiments");
        let (commands, augmented) = all.split_at(30);
        let mut worst = [0.0f64; 5];
        for (i, c) in commands.iter().enumerate() {
            let cycle = c["cycle"].as_u64().unwrap() as usize;
            assert_eq!(cycle, i / 6 + 1);
            let command = c["command"].as_f64().unwrap();
            let ratio = RATIOS[usize::from(cycle == 5)][i % 6];
            assert!((command - ratio * max_force).abs() < 1e-9, "{name}: command {i} is {ratio} of the maximum");
            let error = c["error"].as_f64().unwrap();
            assert!((error - (c["reached"].as_f64().unwrap() - command).abs()).abs() < 1e-9);
            // Graded on the simulator's true force, the sensor's reading beside it (a drifting sensor:
            // the two part by at most its drift since the last tare).
            let measured = c["reached_measured"].as_f64().unwrap();
            assert!((c["error_measured"].as_f64().unwrap() - (measured - command).abs()).abs() < 1e-9);
            assert!((measured - c["reached"].as_f64().unwrap()).abs() < 1.0, "{name}: sensor and truth part");
            assert_eq!(c["model"], "identified");
            worst[cycle - 1] = worst[cycle - 1].max(error / command);
        }
        eprintln!("{name}: largest relative error per cycle {worst:.4?}");
        assert!(worst[0] < 0.10, "{name}: cycle 1 within 10 %: {}", worst[0]);
        for (c, w) in worst.iter().enumerate().skip(1) {
            assert!(*w < 0.02, "{name}: cycle {} within 2 %: {w}", c + 1);
        }
        // The sine-identified model is biased for slow moves; the online update removes the bias.
        let later = worst[1..].iter().copied().fold(0.0, f64::max);
        assert!(worst[0] > 2.0 * later, "{name}: the online update has work to do ({} vs {later})", worst[0]);

        // Cycle 1 again through the model the discrepancy workflow augmented from the identification
        // runs, and the estimator carrying its effects after: every command within 1 %, on the true force.
        let mut worst_augmented = [0.0f64; 5];
        for (i, c) in augmented.iter().enumerate() {
            assert_eq!(c["model"], "augmented");
            let (command, error) = (c["command"].as_f64().unwrap(), c["error"].as_f64().unwrap());
            assert!((command - commands[i]["command"].as_f64().unwrap()).abs() < 1e-9, "{name}: the same commands");
            let cycle = c["cycle"].as_u64().unwrap() as usize;
            worst_augmented[cycle - 1] = worst_augmented[cycle - 1].max(error / command);
        }
        eprintln!("{name}: through the augmented model {worst_augmented:.4?}");
        for (c, w) in worst_augmented.iter().enumerate() {
            assert!(*w < 0.01, "{name}: cycle {} through the augmented model within 1 %: {w}", c + 1);
        }
        // What was named from the identification runs alone is what the cell hides: the two relaxation
        // branches, the hysteresis and the sensor's drift, nothing else.
        let d = &s["discrepancy"];
        let mut named: Vec<&str> = d["named"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
        named.sort();
        assert_eq!(
            named,
            ["hysteresis", "sensor_drift", "viscoelastic_relaxation", "viscoelastic_relaxation"],
            "{name}: {d}"
        );
        assert_eq!(d["remaining"], "none");

        check_recording(&out.join(format!("{name}.mcap")), all);
        // The recording is what `identify` reads: it chooses the same kind from the whole run.
        let identified = out.join(format!("{name}_identify.json"));
        let id = Command::new(env!("CARGO_BIN_EXE_softcontact"))
            .arg("identify")
            .arg(out.join(format!("{name}.mcap")))
            .arg("--json")
            .arg(&identified)
            .output()
            .unwrap();
        assert!(id.status.success(), "identify: {}", String::from_utf8_lossy(&id.stderr));
        let id: Value = serde_json::from_slice(&std::fs::read(&identified).unwrap()).unwrap();
        assert_eq!(id["selected"], kind, "{name}: identify on the demo's recording");

        // The discrepancy workflow names what the simulated cell hides — the surface's relaxation and
        // hysteresis, and the sensor's drift over the 80 s between the start-up tare and control's — and
        // nothing else, and closes the gap.
        let found = out.join(format!("{name}_discrepancy.json"));
        let run = Command::new(env!("CARGO_BIN_EXE_softcontact"))
            .arg("discrepancy")
            .arg(out.join(format!("{name}.mcap")))
            .arg("--out")
            .arg(&out)
            .arg("--json")
            .arg(&found)
            .output()
            .unwrap();
        let shown = String::from_utf8_lossy(&run.stdout);
        assert!(run.status.success(), "discrepancy: {shown}{}", String::from_utf8_lossy(&run.stderr));
        let found: Value = serde_json::from_slice(&std::fs::read(&found).unwrap()).unwrap();
        let mut ids: Vec<&str> =
            found["effects"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
        ids.sort();
        ids.dedup();
        assert_eq!(ids, ["hysteresis", "sensor_drift", "viscoelastic_relaxation"], "{name}: {shown}");
        // The Gamma's drift along the normal (the hand faces down: its z axis, 0.004 N/s).
        let drift = found["effects"].as_array().unwrap().iter().find(|e| e["id"] == "sensor_drift").unwrap();
        let rate = drift["parameters"]["rate_n_per_s"].as_f64().unwrap();
        let hidden = softcontact_sim::FtSensorConfig::gamma_drifting().drift[2];
        assert!((rate.abs() / hidden - 1.0).abs() < 0.1, "{name}: drift {rate} N/s named, {hidden} hidden");
        let (before, after) = (found["refit"]["rms"].as_f64().unwrap(), found["final_rms"].as_f64().unwrap());
        // The augmented model reproduces the recording to the noise floor, and the hidden branches and
        // hysteresis come out with their parameters.
        let sigma = found["noise_floor"].as_f64().unwrap();
        assert_eq!(found["remaining"], "none", "{name}: {shown}");
        assert!(after <= 1.2 * sigma, "{name}: in-contact RMS {before} → {after} N, σ {sigma} N\n{shown}");
        let mut branches: Vec<(f64, f64)> = found["effects"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["id"] == "viscoelastic_relaxation")
            .map(|e| {
                let p = &e["parameters"];
                (p["time_constant_s"].as_f64().unwrap(), p["stiffness_n_per_m"].as_f64().unwrap())
            })
            .collect();
        branches.sort_by(|a, b| a.0.total_cmp(&b.0));
        let hidden: Vec<(f64, f64)> = spec_branches(name);
        assert_eq!(branches.len(), 2, "{name}: {shown}");
        for ((tau, km), (tau_hidden, km_hidden)) in branches.iter().zip(&hidden) {
            assert!((tau / tau_hidden - 1.0).abs() < 0.05, "{name}: τ {tau} s named, {tau_hidden} s hidden");
            assert!((km / km_hidden - 1.0).abs() < 0.05, "{name}: k_m {km} N/m named, {km_hidden} N/m hidden");
        }
        assert!(
            out.join(format!("{name}.residual.svg")).exists() && out.join(format!("{name}.augmented.yaml")).exists()
        );
    }
    // The arm's own effects: named exactly from free-space motion (the hidden payload within 3 %), written
    // as the controller's overlay, and compensated: the tracking gap shrinks.
    let arm = &report["arm"];
    assert_eq!(arm["named_ids"], serde_json::json!(["joint_friction", "payload_mass"]), "{arm}");
    let (named, hidden) = (&arm["named"]["payload"]["mass"], &arm["hidden"]["payload"]["mass"]);
    assert!((named.as_f64().unwrap() / hidden.as_f64().unwrap() - 1.0).abs() < 0.03, "payload {named} for {hidden}");
    assert!(Path::new(arm["overlay_file"].as_str().unwrap()).exists());
    // (The compensation carries the payload and 80 % of the Coulomb friction: the viscous friction is left
    // to damp, and what it costs shows across the surface.)
    let (without, with) = (&arm["without_compensation"], &arm["with_compensation"]);
    for (what, gain) in [("deformation_rms", 0.1), ("worst_force_error", 0.1), ("lateral_rms", 0.8)] {
        let (a, b) = (without[what].as_f64().unwrap(), with[what].as_f64().unwrap());
        eprintln!("arm: {what} {a:.5} without compensation, {b:.5} with");
        assert!(b < gain * a, "{what}: {a} without compensation, {b} with");
    }
    assert!(with["worst_force_error"].as_f64().unwrap() < 0.03, "{with}");

    for figure in [
        "fig2_identification.svg",
        "fig3_control_sponge.svg",
        "fig4_control_dice.svg",
        "fig3_control_sponge_augmented.svg",
        "fig4_control_dice_augmented.svg",
    ] {
        let svg = std::fs::read_to_string(out.join(figure)).unwrap();
        assert!(svg.starts_with("<svg") && svg.matches("<polyline").count() >= 3, "{figure} has curves");
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// The relaxation branches (τ [s], k_m [N/m]) the demo's simulated surface hides, fastest first.
fn spec_branches(name: &str) -> Vec<(f64, f64)> {
    let truth = if name == "sponge" { softcontact_sim::lab_sponge() } else { softcontact_sim::lab_dice() };
    let mut branches: Vec<(f64, f64)> = truth
        .effects
        .iter()
        .filter_map(|e| match *e {
            softcontact_contact::Effect::ViscoelasticRelaxation { stiffness, time_constant } => {
                Some((time_constant, stiffness))
            }
            _ => None,
        })
        .collect();
    branches.sort_by(|a, b| a.0.total_cmp(&b.0));
    branches
}

/// The recording holds the graph's topics at their rates, and the 30 force commands of the report.
fn check_recording(path: &Path, commands: &[Value]) {
    let rec = softcontact_bag::Recording::open(path).unwrap();
    assert!(rec.warnings().is_empty(), "{:?}", rec.warnings());
    let (t0, t1) = rec.time_range().unwrap();
    let seconds = (t1 - t0) as f64 * 1e-9;
    for (topic, rate) in
        [("/ft_sensor/wrench", 1000.0), ("/lwr/ee_pose", 1000.0), ("/deformation_controller/state", 100.0)]
    {
        let n = rec.topic(topic).map_or(0, |t| t.message_count) as f64;
        assert!(n > 0.95 * rate * seconds, "{topic}: {n} messages in {seconds} s");
    }
    assert!(rec.topic("/tf_static").is_some_and(|t| t.message_count == 1));
    let recorded: Vec<f64> = rec
        .messages()
        .map(Result::unwrap)
        .filter(|m| m.topic() == "/deformation_controller/force_command")
        .map(|m| m.decode::<ForceCommand>().unwrap().force)
        .collect();
    let reported: Vec<f64> = commands.iter().map(|c| c["command"].as_f64().unwrap()).collect();
    assert_eq!(recorded, reported);
}
