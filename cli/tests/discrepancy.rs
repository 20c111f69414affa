//! `softcontact discrepancy` on recordings made from a contact model whose hidden effects are known
//! (the readings are stepped with the model's own effect code; the command reads only the recording):
//! a hidden relaxation of the surface is named, a clean recording gets no name, and bad input is refused
//! clearly.

use std::path::Path;
use std::process::{Command, Output};

use softcontact_bag::{BagWriter, Qos};
use softcontact_contact::{ContactModel, Effect, Kind};
use softcontact_msgs::geometry_msgs::{PoseStamped, TwistStamped, WrenchStamped};
use softcontact_nodes::contact_estimator::identify::synthetic_pushes;

fn write(path: &Path, model: &ContactModel, seed: u64) {
    write_readings(path, &synthetic_pushes(model, 0.3, 0.03, 20.0, 1000.0, 0.1, seed).unwrap());
}

fn write_readings(path: &Path, readings: &[softcontact_nodes::contact_estimator::identify::SyntheticReading]) {
    let mut w = BagWriter::create(path).unwrap();
    let pose = w.add_topic::<PoseStamped>("/lwr/ee_pose", Qos::SENSOR).unwrap();
    let twist = w.add_topic::<TwistStamped>("/lwr/ee_twist", Qos::SENSOR).unwrap();
    let wrench = w.add_topic::<WrenchStamped>("/ft_sensor/wrench", Qos::SENSOR).unwrap();
    let ns = |t: f64| (1.7e18 + t * 1e9) as u64;
    for r in readings {
        w.write(pose, ns(r.t), &r.pose).unwrap();
        w.write(twist, ns(r.t), &r.twist).unwrap();
        w.write(wrench, ns(r.t), &r.wrench).unwrap();
    }
    w.finish().unwrap();
}

fn discrepancy(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_softcontact")).arg("discrepancy").args(args).output().unwrap()
}

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// Runs the command on `model`'s recording; the JSON and the augmented model it wrote.
fn analyse(dir: &Path, name: &str, model: &ContactModel) -> (serde_json::Value, ContactModel, String) {
    let (path, json, out) = (dir.join(format!("{name}.mcap")), dir.join(format!("{name}.json")), dir.join("out"));
    write(&path, model, 3);
    let run = discrepancy(&[path.as_os_str(), "--json".as_ref(), json.as_os_str(), "--out".as_ref(), out.as_os_str()]);
    let shown = text(&run);
    assert!(run.status.success(), "{shown}");
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let file = report["model_file"].as_str().unwrap_or_else(|| panic!("model_file in {report}"));
    let augmented = ContactModel::from_yaml(&std::fs::read_to_string(file).unwrap()).unwrap();
    (report, augmented, shown)
}

fn ids(report: &serde_json::Value) -> Vec<String> {
    report["effects"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap().to_string()).collect()
}

#[test]
fn a_clean_recording_gets_no_name() {
    let dir = tempfile::tempdir().unwrap();
    let clean = ContactModel::new(Kind::AzadFeatherstone, 25_000.0, 1100.0).unwrap();
    let (report, augmented, shown) = analyse(dir.path(), "clean", &clean);
    assert_eq!(ids(&report), Vec::<String>::new(), "{shown}");
    assert_eq!(report["remaining"], "none", "{shown}");
    assert!(augmented.effects.is_empty() && augmented.kind == Kind::AzadFeatherstone, "{augmented:?}");
}

/// A relaxation the baseline lacks moves identify's onset; the workflow refits the surface with the effects
/// and names it. "Named exactly" is the set of ids (a relaxation may come out as two branches), and the gap
/// shrinks by at least 80 % of the ideal 1 − σ / baseline RMS (the goals).
#[test]
fn a_hidden_relaxation_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let clean = ContactModel::new(Kind::AzadFeatherstone, 25_000.0, 1100.0).unwrap();
    let mut relaxing = clean.clone();
    relaxing.effects.push(Effect::ViscoelasticRelaxation { stiffness: 300.0, time_constant: 0.3 });
    let (report, augmented, shown) = analyse(dir.path(), "relaxing", &relaxing);
    let mut named = ids(&report);
    named.dedup();
    assert_eq!(named, ["viscoelastic_relaxation"], "{shown}");
    // The stiffest branch carries the hidden time constant.
    let branch = report["effects"]
        .as_array()
        .unwrap()
        .iter()
        .max_by(|a, b| {
            let k = |e: &serde_json::Value| e["parameters"]["stiffness_n_per_m"].as_f64().unwrap();
            k(a).total_cmp(&k(b))
        })
        .unwrap();
    let tau = branch["parameters"]["time_constant_s"].as_f64().unwrap();
    assert!((tau / 0.3 - 1.0).abs() < 0.3, "τ {tau} s named, 0.3 s hidden\n{shown}");
    assert!(augmented.effects.iter().any(|e| e.id() == "viscoelastic_relaxation"), "{augmented:?}");
    // The graph's overlay, read by the nodes' own loaders: the controller starts from the augmented model
    // with its surface placed, the estimator carries its effects with the surface held there (at 0.3 m).
    let overlay = report["overlay_file"].as_str().unwrap_or_else(|| panic!("overlay_file in {report}"));
    let args = softcontact_nodes::runtime::params::ParamArgs { files: vec![overlay.into()], ..Default::default() };
    let (controller, _) =
        softcontact_nodes::runtime::params::load::<softcontact_nodes::deformation_controller::Params>(
            "deformation_controller",
            &args,
        )
        .unwrap();
    let (estimator, _) = softcontact_nodes::runtime::params::load::<softcontact_nodes::contact_estimator::Params>(
        "contact_estimator",
        &args,
    )
    .unwrap();
    assert_eq!(controller.initial_model, augmented);
    assert_eq!(estimator.augmented_model.as_ref(), Some(&augmented));
    let surface = controller.initial_surface.unwrap();
    assert_eq!(estimator.surface_position, Some(surface));
    assert!((surface[2] - 0.3).abs() < 1e-3, "surface placed at {surface:?}\n{shown}");
    let (before, after) = (report["refit"]["rms"].as_f64().unwrap(), report["final_rms"].as_f64().unwrap());
    let ideal = 1.0 - report["noise_floor"].as_f64().unwrap() / before;
    assert!(1.0 - after / before >= 0.8 * ideal, "RMS {before} → {after}, ideal shrink {ideal}\n{shown}");
}

#[test]
fn bad_input_gets_a_clear_error_and_a_non_zero_exit() {
    let dir = tempfile::tempdir().unwrap();
    let recording = dir.path().join("clean.mcap");
    write(&recording, &ContactModel::new(Kind::KelvinVoigt, 9000.0, 250.0).unwrap(), 4);
    let garbage = dir.path().join("model.yaml");
    std::fs::write(&garbage, "kind: kelvin_voigt\nstiffness: -5\n").unwrap();
    let missing = dir.path().join("missing.mcap");
    let curve = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/afm/brain_creep.csv");
    // Tables whose force says why no contact is found: constant, pulling, a single sample above the onset.
    let table = |name: &str, force: &dyn Fn(usize) -> f64| {
        let rows: String = (0..300).map(|i| format!("{},{i},{}\n", i as f64 * 1e-3, force(i))).collect();
        let path = dir.path().join(name);
        std::fs::write(&path, format!("t [s],x [nm],f [nN]\n{rows}")).unwrap();
        path
    };
    let constant = table("constant.csv", &|_| 2.0);
    let pulling = table("pulling.csv", &|i| -0.01 * i as f64 - 0.001 * (i % 3) as f64);
    let one_sample = table("one.csv", &|i| if i == 299 { 5.0 } else { 0.001 * (i % 3) as f64 });
    for (args, says) in [
        (vec![constant.as_os_str()], "the force is 2.000 nN on every row: nothing touches"),
        (vec![pulling.as_os_str()], "f > 0 must push (negate the column"),
        (vec![one_sample.as_os_str()], "on at most 1 sample in a row; a contact needs 3"),
        (vec![curve.as_os_str(), "--normal".as_ref(), "1,0,0".as_ref()], "--normal is for recordings"),
        (vec![recording.as_os_str(), "--model".as_ref(), garbage.as_os_str()], "not a contact model"),
        (vec![missing.as_os_str()], "missing.mcap"),
        (vec![recording.as_os_str(), "--normal".as_ref(), "0,0".as_ref()], "--normal"),
    ] {
        let out = discrepancy(&args);
        let shown = text(&out);
        assert!(!out.status.success(), "{args:?} succeeded:\n{shown}");
        assert!(shown.contains(says) && !shown.contains("panicked"), "{args:?}: {shown}");
    }
}

/// A force reading the sensor cannot have made (not finite, or beyond 10 MN) is left out and said, and the
/// analysis is that of the recording without it: one reading of 1e9 N took the noise floor to 1 N.
#[test]
fn force_readings_of_nan_inf_1e9_and_1e300_are_left_out_said_and_change_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let model = ContactModel::new(Kind::KelvinVoigt, 9000.0, 250.0).unwrap();
    let mut readings = synthetic_pushes(&model, 0.3, 0.03, 20.0, 1000.0, 0.1, 6).unwrap();
    let run = |name: &str, readings: &[_]| {
        let (path, json) = (dir.path().join(format!("{name}.mcap")), dir.path().join(format!("{name}.json")));
        write_readings(&path, readings);
        let out = dir.path().join(name);
        let run =
            discrepancy(&[path.as_os_str(), "--json".as_ref(), json.as_os_str(), "--out".as_ref(), out.as_os_str()]);
        assert!(run.status.success(), "{}", text(&run));
        (text(&run), serde_json::from_slice::<serde_json::Value>(&std::fs::read(&json).unwrap()).unwrap())
    };
    let (_, clean) = run("clean", &readings);
    let n = readings.len();
    for (k, bad) in [(n / 5, f64::NAN), (n / 3, 1e9), (n / 2, -1e300), (2 * n / 3, f64::INFINITY)] {
        readings[k].wrench.wrench.force.z = bad;
    }
    let (shown, corrupted) = run("corrupted", &readings);
    assert!(shown.contains("warning: 4 force readings left out: not finite or beyond 1e7 N"), "{shown}");
    assert_eq!(ids(&corrupted), ids(&clean), "{shown}");
    assert_eq!(corrupted["remaining"], clean["remaining"], "{shown}");
    for key in ["noise_floor", "final_rms"] {
        let (a, b) = (clean[key].as_f64().unwrap(), corrupted[key].as_f64().unwrap());
        assert!((a - b).abs() <= 0.05 * a, "{key}: clean {a}, corrupted {b}\n{shown}");
    }
}

#[test]
fn a_damaged_chunk_is_reported_by_discrepancy_as_by_identify() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("damaged.mcap");
    write(&path, &ContactModel::new(Kind::KelvinVoigt, 9000.0, 250.0).unwrap(), 5);
    let mut bytes = std::fs::read(&path).unwrap();
    // The middle of the file lies in a chunk (a recording is chunks, then its summary).
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0xFF;
    std::fs::write(&path, &bytes).unwrap();
    let out = dir.path().join("out");
    let run = discrepancy(&[path.as_os_str(), "--out".as_ref(), out.as_os_str()]);
    let shown = text(&run);
    assert!(shown.contains("warning:") && shown.contains("damaged"), "{shown}");
}

/// The hidden-effect corpus made in the lockstep cell (`softcontact bench discrepancy`, the table in
/// docs/discrepancy-corpus.md) meets the goals: ≥ 90 % of effect cases named exactly, no false
/// name on ≥ 20 nulls, median gap shrink ≥ 80 % of the ideal; and the foreign-effect corpus beside it.
#[test]
fn the_hidden_effect_corpus_meets_its_goals() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("corpus.json");
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["bench", "discrepancy", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    let shown = text(&out);
    assert!(out.status.success(), "{shown}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let c = &v["corpus"];
    let count = |key: &str| c[key].as_u64().unwrap();
    assert!(count("effect_cases") >= 12 && count("null_cases") >= 20, "{shown}");
    assert!(count("named_exactly") * 10 >= 9 * count("effect_cases"), "{shown}");
    assert_eq!(count("false_names_on_nulls"), 0, "{shown}");
    assert!(count("out_of_library_cases") >= 1, "{shown}");
    assert_eq!(count("out_of_library_unexplained"), count("out_of_library_cases"), "{shown}");
    // Where the recording cannot separate two effects (a sensor drift and a creeping surface through one
    // long hold), the answer is "ambiguous", with no name.
    assert!(count("ambiguous_cases") >= 2, "{shown}");
    assert_eq!(count("ambiguous_answered"), count("ambiguous_cases"), "{shown}");
    // Every effect id of the cell's surface and sensor is hidden at least once.
    let hidden: std::collections::BTreeSet<&str> = c["outcomes"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|o| o["expected"].as_array().unwrap())
        .filter_map(|v| v.as_str())
        .collect();
    for id in [
        "viscoelastic_relaxation",
        "hysteresis",
        "stiffness_exponent",
        "contact_offset_drift",
        "sensor_drift",
        "time_delay",
        "sensor_crosstalk",
        "tool_gravity",
        "adhesion",
        "quasi_linear_relaxation",
    ] {
        assert!(hidden.contains(id), "{id} is never hidden: {shown}");
    }
    assert!(c["median_shrink_of_ideal"].as_f64().unwrap() >= 0.8, "{shown}");

    // The foreign-effect corpus (effects written outside the library): no false name on its coloured
    // nulls, and where a parameter is checked — the sensor turned about an arbitrary axis (the coupling
    // within 0.05° of n × ω, the gap closed by 90 % of the ideal), a lag of no whole number of steps
    // (within 0.5 ms) — it is found.
    let f = &v["foreign_corpus"];
    let count = |key: &str| f[key].as_u64().unwrap();
    assert!(count("effect_cases") >= 13 && count("null_cases") >= 4, "{shown}");
    assert_eq!(count("false_names_on_nulls"), 0, "{shown}");
    // Both corpora together (issue 37's goals): ≥ 90 % answered as expected, no false name on ≥ 30 nulls,
    // median shrink ≥ 85 % of the ideal.
    let both = |key: &str| c[key].as_u64().unwrap() + f[key].as_u64().unwrap();
    assert!(both("named_exactly") * 10 >= 9 * both("effect_cases"), "{shown}");
    assert!(both("null_cases") >= 30, "{shown}");
    let mut shrinks: Vec<f64> = [c, f]
        .iter()
        .flat_map(|corpus| corpus["outcomes"].as_array().unwrap())
        .filter_map(|o| o["shrink_of_ideal"].as_f64())
        .collect();
    shrinks.sort_by(f64::total_cmp);
    assert!(shrinks[shrinks.len() / 2] >= 0.85, "median shrink {}\n{shown}", shrinks[shrinks.len() / 2]);
    // A baseline of the wrong kind given (issue 37: fixed, not patched): the kind is re-chosen as the
    // truth's and only what is hidden is named.
    let given: Vec<&serde_json::Value> =
        f["outcomes"].as_array().unwrap().iter().filter(|o| !o["expected_law"].is_null()).collect();
    assert!(given.len() >= 3, "{shown}");
    for o in given {
        assert!(o["exact"].as_bool().unwrap() && o["law_rechosen"].is_string(), "{o}\n{shown}");
    }
    let checked: Vec<&serde_json::Value> =
        f["outcomes"].as_array().unwrap().iter().filter(|o| !o["parameters"].as_array().unwrap().is_empty()).collect();
    assert!(checked.len() >= 4, "{shown}");
    for o in checked {
        assert!(o["exact"].as_bool().unwrap() && o["parameters_within"].as_bool().unwrap(), "{o}\n{shown}");
        if o["expected"][0] == "sensor_crosstalk" {
            assert!(o["shrink_of_ideal"].as_f64().unwrap() >= 0.9, "{o}\n{shown}");
        }
    }
}

/// Recordings a lab's own logger would write, by both Python writers (mcap-ros2-support: one .mcap file;
/// rosbags: a rosbag2 folder), at 500 Hz and 1 kHz, the wrench stamped 1 ms after the pose, of a foam with
/// a relaxation branch (300 N/m, 0.5 s) that `cli/tests/discrepancy_peers.py` computes on its own: the
/// workflow names the relaxation, nothing else, with its parameters, and closes the gap.
#[test]
fn recordings_written_by_python_peers_are_analysed() {
    let dir = tempfile::tempdir().unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/discrepancy_peers.py");
    for rate in ["500", "1000"] {
        let folder = dir.path().join(rate);
        let out = Command::new("python3").arg(&script).arg("write").arg(&folder).arg(rate).output().unwrap();
        assert!(out.status.success(), "discrepancy_peers.py: {}", text(&out));
        for recording in [folder.join("by_mcap_ros2.mcap"), folder.join("by_rosbags")] {
            let json = folder.join("report.json");
            let run = discrepancy(&[
                recording.as_os_str(),
                "--json".as_ref(),
                json.as_os_str(),
                "--out".as_ref(),
                folder.join("out").as_os_str(),
            ]);
            let shown = text(&run);
            assert!(run.status.success(), "{shown}");
            let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
            assert_eq!(ids(&report), ["viscoelastic_relaxation"], "{rate} Hz {recording:?}\n{shown}");
            let p = &report["effects"][0]["parameters"];
            let (k_m, tau) = (p["stiffness_n_per_m"].as_f64().unwrap(), p["time_constant_s"].as_f64().unwrap());
            assert!((k_m / 300.0 - 1.0).abs() < 0.05 && (tau / 0.5 - 1.0).abs() < 0.05, "{k_m} N/m, {tau} s\n{shown}");
            let (before, after) = (report["refit"]["rms"].as_f64().unwrap(), report["final_rms"].as_f64().unwrap());
            let ideal = 1.0 - report["noise_floor"].as_f64().unwrap() / before;
            assert!(1.0 - after / before >= 0.8 * ideal, "RMS {before} → {after}, ideal {ideal}\n{shown}");
        }
    }
}

/// The residual of every wrench channel: on a surface with a Walton tangential law and friction, swayed
/// sideways in the lockstep cell (the corpus's misaligned-sensor case, kept), a model without a tangential
/// law leaves the whole tangential load and its torque in the tangential channels; the same law with the
/// tangential law predicts all six channels to their free-space noise. The simulator's sensor computes
/// the torque with its own code (`FtSensor::true_wrench`); the workflow from the URDF's tool → sensor pose.
#[test]
fn every_wrench_channel_is_predicted_to_its_noise_with_the_tangential_law() {
    let dir = tempfile::tempdir().unwrap();
    let kept = dir.path().join("kept");
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["bench", "discrepancy", "--case", "dice: sensor axis misaligned", "--keep"])
        .arg(&kept)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let recording = std::fs::read_dir(&kept)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("the kept recording");
    let channels = |model: Option<&Path>| -> Vec<(String, f64, f64)> {
        let json = dir.path().join("wrench.json");
        let mut args: Vec<&std::ffi::OsStr> = vec![
            recording.as_os_str(),
            "--normal".as_ref(),
            "0,0,-1".as_ref(),
            "--json".as_ref(),
            json.as_os_str(),
            "--out".as_ref(),
            dir.path().as_os_str(),
        ];
        if let Some(m) = model {
            args.extend(["--model".as_ref(), m.as_os_str()]);
        }
        let run = discrepancy(&args);
        assert!(run.status.success(), "{}", text(&run));
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        v["locate"]["channels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                let name = c["channel"].as_str().unwrap().to_string();
                (name, c["rms_after"].as_f64().unwrap(), c["noise_floor"].as_f64().unwrap())
            })
            .collect()
    };
    let without = channels(None);
    assert_eq!(without.len(), 6, "{without:?}");
    let worst = without.iter().map(|(_, rms, sigma)| rms / sigma).fold(0.0, f64::max);
    assert!(worst > 100.0, "a model without a tangential law misses the tangential load: {without:?}");
    // The corpus's dice law (the force-control paper's dice) and its tangential law, as the simulator's surface has them.
    let mut law = ContactModel::new(Kind::KelvinVoigt, 130.0 / 0.07, 60.0).unwrap();
    law.tangential = Some(softcontact_contact::Tangential::walton(1.0e4, 0.8));
    let model = dir.path().join("law.yaml");
    std::fs::write(&model, law.to_yaml()).unwrap();
    for (name, rms, sigma) in channels(Some(&model)) {
        assert!(rms < 1.3 * sigma, "{name}: RMS {rms} against free-space σ {sigma}");
    }
}

/// The snake paper's loading paths (`softcontact loading-paths --out`) with the paper's two named errors and the
/// specimen's tangential law hidden case by case; `softcontact discrepancy` reads only the two-segment
/// recording. Each case: the arguments that hide the effects, and the ids that must be named.
#[test]
fn the_loading_path_corpus_names_the_papers_errors_and_the_path_dependence() {
    let dir = std::env::temp_dir().join(format!("softcontact-path-corpus-{}", std::process::id()));
    let cases: [(&str, &[&str], &[&str]); 8] = [
        ("null", &["--stage", "ideal", "--law", "walton", "--creep-um", "0", "--misalignment-deg", "0"], &[]),
        (
            "null, seed 7",
            &["--stage", "ideal", "--law", "walton", "--creep-um", "0", "--misalignment-deg", "0", "--seed", "7"],
            &[],
        ),
        (
            "creep 5 µm",
            &["--stage", "ideal", "--law", "walton", "--creep-um", "5", "--misalignment-deg", "0"],
            &["contact_offset_drift"],
        ),
        (
            "misalignment 0.5°",
            &["--stage", "ideal", "--law", "walton", "--creep-um", "0", "--misalignment-deg", "0.5"],
            &["sensor_crosstalk"],
        ),
        (
            "misalignment −0.3°",
            &["--stage", "ideal", "--law", "walton", "--creep-um", "0", "--misalignment-deg", "-0.3"],
            &["sensor_crosstalk"],
        ),
        (
            "path dependence",
            &["--stage", "ideal", "--law", "mindlin-deresiewicz", "--creep-um", "0", "--misalignment-deg", "0"],
            &["tangential_history"],
        ),
        ("arm, null", &["--stage", "arm", "--law", "walton", "--creep-um", "0", "--misalignment-deg", "0"], &[]),
        (
            "arm, all three",
            &["--stage", "arm", "--law", "mindlin-deresiewicz", "--creep-um", "5", "--misalignment-deg", "0.5"],
            &["contact_offset_drift", "sensor_crosstalk", "tangential_history"],
        ),
    ];
    for (name, hide, expected) in cases {
        let _ = std::fs::remove_dir_all(&dir);
        let made = Command::new(env!("CARGO_BIN_EXE_softcontact"))
            .arg("loading-paths")
            .args(hide)
            .arg("--out")
            .arg(&dir)
            .output()
            .unwrap();
        assert!(made.status.success(), "{name}: {}", text(&made));
        let json = dir.join("discrepancy.json");
        let recording = dir.join("two_segment.mcap");
        let out =
            discrepancy(&[recording.as_os_str(), "--loading-paths".as_ref(), "--json".as_ref(), json.as_os_str()]);
        assert!(out.status.success(), "{name}: {}", text(&out));
        let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let mut named: Vec<String> =
            report["named_ids"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect();
        named.sort();
        eprintln!("{name}: named {named:?}; {}", text(&out).lines().last().unwrap_or(""));
        assert_eq!(named, expected, "{name}: {}", text(&out));
        // The parameters of what was named are the hidden ones (k_t 3.7482 N/mm^1.5; ε; creep sd 5 µm).
        let k_t = report["k_t"].as_f64().unwrap() / softcontact_contact::N_PER_MM_1_5;
        assert!((k_t / 3.7482 - 1.0).abs() < 0.03, "{name}: k_t {k_t}");
        let epsilon = report["misalignment"].as_f64().unwrap().to_degrees();
        let hidden_epsilon: f64 =
            hide[hide.iter().position(|a| *a == "--misalignment-deg").unwrap() + 1].parse().unwrap();
        assert!((epsilon - hidden_epsilon).abs() <= 0.05 + 0.25 * hidden_epsilon.abs(), "{name}: ε {epsilon}°");
        if expected.contains(&"contact_offset_drift") {
            let sd = report["creep_sd"].as_f64().unwrap() * 1e6;
            assert!((sd / 5.0 - 1.0).abs() < 0.2, "{name}: creep sd {sd} µm");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A recording of the arm's free-space excitation in the simulator, friction and a flange payload hidden
/// in its physics: joint states and the torque commands that answered them, as the graph records them.
fn write_arm_run(path: &Path, hidden: bool) {
    use softcontact_msgs::builtin_interfaces::Time;
    use softcontact_msgs::sensor_msgs::JointState;
    use softcontact_msgs::std_msgs::Header;
    use softcontact_sim::{FtSensorConfig, JointFriction, Payload, SimConfig, excitation};
    let config = SimConfig {
        surface: None,
        sensor: FtSensorConfig::ideal(),
        friction: hidden.then_some(JointFriction {
            viscous: [0.8, 0.8, 0.5, 0.5, 0.3, 0.2, 0.2],
            coulomb: [0.5, 0.5, 0.25, 0.25, 0.2, 0.05, 0.05],
        }),
        payload: hidden.then_some(Payload { mass: 1.2, com: [0.01, -0.02, 0.03] }),
        ..SimConfig::above_surface(ContactModel::new(Kind::KelvinVoigt, 1.0, 0.0).unwrap(), 5)
    };
    let run = excitation::excite(config, 8.0).unwrap();
    let mut w = BagWriter::create(path).unwrap();
    let states = w.add_topic::<JointState>("/lwr/joint_states", Qos::SENSOR).unwrap();
    let commands = w.add_topic::<JointState>("/lwr/joint_torque_command", Qos::RELIABLE).unwrap();
    for s in &run {
        let ns = (s.t * 1e9).round() as u64 + 1_000_000_000;
        let header = Header {
            stamp: Time { sec: (ns / 1_000_000_000) as i32, nanosec: (ns % 1_000_000_000) as u32 },
            frame_id: String::new(),
        };
        let js = JointState {
            header: header.clone(),
            position: s.q.to_vec(),
            velocity: s.dq.to_vec(),
            ..Default::default()
        };
        w.write(states, ns, &js).unwrap();
        w.write(commands, ns + 200_000, &JointState { header, effort: s.tau.to_vec(), ..Default::default() }).unwrap();
    }
    w.finish().unwrap();
}

/// `softcontact discrepancy --arm`: the hidden friction and payload named from the recording with their
/// values; a clean arm names nothing.
#[test]
fn the_arms_own_effects_are_named_from_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    for hidden in [true, false] {
        let file = dir.path().join(format!("arm_{hidden}.mcap"));
        let json = dir.path().join(format!("arm_{hidden}.json"));
        write_arm_run(&file, hidden);
        let folder = dir.path().join(format!("out_{hidden}"));
        let out = discrepancy(&[
            file.as_os_str(),
            "--arm".as_ref(),
            "--json".as_ref(),
            json.as_os_str(),
            "--out".as_ref(),
            folder.as_os_str(),
        ]);
        assert!(out.status.success(), "{}", text(&out));
        // The compensation file is the controller's parameter overlay, read as the node reads it.
        let overlay = folder.join("arm_effects.yaml");
        let args = softcontact_nodes::runtime::params::ParamArgs { files: vec![overlay], ..Default::default() };
        let (params, _) =
            softcontact_nodes::runtime::params::load::<softcontact_nodes::deformation_controller::Params>(
                "deformation_controller",
                &args,
            )
            .unwrap();
        let compensated = params.arm_effects;
        assert_eq!(compensated.joint_friction.is_some(), hidden);
        assert_eq!(compensated.payload.map(|p| (p.mass - 1.2).abs() < 0.03), hidden.then_some(true));
        let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert_eq!(report["kind"], "arm");
        let named: Vec<&str> = report["named"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
        if hidden {
            assert_eq!(named, ["joint_friction", "payload_mass"], "{}", text(&out));
            let mass = report["named"][1]["mass"].as_f64().unwrap();
            assert!((mass - 1.2).abs() < 0.03, "payload {mass} kg");
            let b0 = report["named"][0]["viscous"][0].as_f64().unwrap();
            assert!((b0 - 0.8).abs() < 0.04, "viscous {b0}");
        } else {
            assert!(named.is_empty(), "{}", text(&out));
        }
    }
}

/// The closed-loop replay: the lab sponge's recording (the corpus case: identification pushes, then six
/// force commands through the identified model) replayed through the simulated cell on the identified
/// model and on the augmented one. The simulator behaves like the recorded cell only with the named
/// effects added: every signal's gap shrinks, the force's at least halves.
#[test]
fn the_closed_loop_replay_matches_the_recording_after_the_effects_are_added() {
    let dir = tempfile::tempdir().unwrap();
    let kept = dir.path().join("kept");
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["bench", "discrepancy", "--case", "lab sponge (the demo's surface)", "--keep"])
        .arg(&kept)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let recording = std::fs::read_dir(&kept)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("the kept recording");
    let json = dir.path().join("closed_loop.json");
    let run = discrepancy(&[
        recording.as_os_str(),
        "--closed-loop".as_ref(),
        "--json".as_ref(),
        json.as_os_str(),
        "--out".as_ref(),
        dir.path().as_os_str(),
    ]);
    assert!(run.status.success(), "{}", text(&run));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let c = &v["closed_loop"];
    assert_eq!(c["commands"], 6, "{c}");
    for (signal, shrink) in [("force_n", 0.5), ("deformation_m", 0.8), ("joints_rad", 0.8)] {
        let (before, after) = (c["rms_before"][signal].as_f64().unwrap(), c["rms_after"][signal].as_f64().unwrap());
        eprintln!("{signal}: {before:.5} on the baseline model, {after:.5} on the augmented one");
        assert!(after < shrink * before, "{signal}: {before} before, {after} after\n{}", text(&run));
    }
    let svg = std::fs::read_to_string(c["figure"].as_str().unwrap()).unwrap();
    assert!(svg.starts_with("<svg") && svg.matches("<polyline").count() >= 9, "three panels of three curves");
    // Without force commands there is nothing to replay: a clear error, after the report, the model file,
    // the figures and the JSON are written (they were not, and the analysis was lost).
    let pushes = dir.path().join("pushes.mcap");
    write(&pushes, &ContactModel::new(Kind::KelvinVoigt, 9000.0, 250.0).unwrap(), 8);
    let (out, json) = (dir.path().join("no_commands"), dir.path().join("no_commands.json"));
    let run = discrepancy(&[
        pushes.as_os_str(),
        "--closed-loop".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
        "--json".as_ref(),
        json.as_os_str(),
    ]);
    let shown = text(&run);
    assert!(!run.status.success(), "{shown}");
    assert!(
        shown.contains("the closed-loop replay failed") && shown.contains("effects named")
            || shown.contains("no effect named"),
        "{shown}"
    );
    for written in ["pushes.augmented.yaml", "pushes.residual.svg", "pushes.loops.svg", "pushes.residual.csv"] {
        assert!(out.join(written).is_file(), "{written} not written:\n{shown}");
    }
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert!(v["model_file"].is_string() && v.get("closed_loop").is_none(), "{v}");
}

/// The measured AFM curves of data/afm (the table in docs/discrepancy-real.md), each against what a
/// person saw in it before the workflow ran: the final model is never worse than the baseline, and where
/// something outside the library is there the answer is never that nothing remains. The curves answered
/// as expected stay so (at least the eight of today's table), and the expected effect stays named on all
/// seven where it is one of the library's; the gap shrinks by at least 60 % of what the noise allows on
/// six of them (the cell's among them: it starts in contact, a pause the table reader does not take for
/// free space; the map's, whose adhesion acts only on the retract, judged by interleaved folds), and on
/// the seventh by today's share less a margin: the single indentation whose retract ends below the free
/// level and whose tip pulls while still indented (flipsign 23 %).
#[test]
fn real_curves_are_never_made_worse_nor_called_explained_when_they_are_not() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("real.json");
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/afm");
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["bench", "discrepancy", "--real", data, "--json"])
        .arg(&json)
        .output()
        .unwrap();
    let shown = text(&out);
    assert!(out.status.success(), "{shown}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let curves = v["real_curves"].as_array().unwrap();
    assert!(curves.len() >= 8, "{shown}");
    for c in curves {
        assert_eq!(c["not_worse"], true, "{c}");
        assert_eq!(c["outside_not_denied"], true, "{c}");
    }
    let as_expected = |c: &&serde_json::Value| {
        c["named_as_expected"] == true && c["outside_not_denied"] == true && c["not_worse"] == true
    };
    assert!(curves.iter().filter(as_expected).count() >= 9, "{shown}");
    // A wave in the free deflection, beyond the onset threshold, is free space: nothing is named.
    let workshop = curves.iter().find(|c| c["file"] == "workshop_indentation.csv").unwrap();
    assert_eq!(workshop["answer"]["Ok"].as_array().map(Vec::len), Some(0), "{workshop}");
    assert_eq!(workshop["named_as_expected"], true, "{workshop}");
    // The holds a person sees relax (two force clamps, one height clamp) are named although the adhesion
    // on each retract dominates the residual (the phase-local rule), and so are the loops of four single
    // indentations, soft and stiff; every named parameter carries its interval.
    for (file, shrink) in [
        ("brain_creep.csv", 0.6),
        ("polymergel_creep.csv", 0.6),
        ("cell_relaxation.csv", 0.6),
        ("reference_indentation.csv", 0.6),
        ("qi_stiff_indentation.csv", 0.6),
        ("flipsign_indentation.csv", 0.25),
        ("map_indentation.csv", 0.6),
    ] {
        let c = curves.iter().find(|c| c["file"] == file).unwrap();
        assert_eq!(c["named_as_expected"], true, "{c}");
        assert!(c["shrink_of_ideal"].as_f64().unwrap() >= shrink, "{c}");
    }
    // The cantilever's drag in the liquid, named on two indentations whose approach and retract cross free
    // space at different speeds: within a factor of 1.5 of what the free levels alone say.
    for file in ["flipsign_indentation.csv", "reference_indentation.csv"] {
        let v = report_of(dir.path(), &format!("{data}/{file}"));
        let drag = v["effects"].as_array().unwrap().iter().find(|e| e["id"] == "medium_drag");
        let damping = drag.map_or(0.0, |e| e["parameters"]["damping_n_s_per_m"].as_f64().unwrap());
        let levels = drag_from_free_levels(&format!("{data}/{file}"));
        assert!(damping > levels / 1.5 && damping < levels * 1.5, "{file}: {damping} N·s/m, the free levels {levels}");
    }
    let v = report_of(dir.path(), &format!("{data}/polymergel_creep.csv"));
    for e in v["effects"].as_array().unwrap() {
        for (name, _) in e["parameters"].as_object().unwrap() {
            assert!(e["uncertainty"][name].as_f64().is_some_and(|u| u >= 0.0), "{e}");
        }
        assert!(e["not_identifiable"].is_array(), "{e}");
    }
    // The tip that only touches: refused, saying which threshold and how to set another.
    let refused = curves.iter().find(|c| c["file"] == "qi_adhesion.csv").unwrap();
    let why = refused["answer"]["Err"].as_str().unwrap();
    assert!(why.contains("onset threshold") && why.contains("--onset"), "{why}");
}

/// `softcontact discrepancy PATH`'s JSON report, its files written to `dir`.
/// Scale-free: a measured AFM curve read at a robot's scale (its nN as N, its nm as µm: ×10⁹ in force,
/// ×10³ in depth, as the sphere indentation was given) names the same effects and closes the same
/// share of its gap, with no flag.
#[test]
fn a_real_curve_read_at_a_robots_scale_names_the_same_and_shrinks_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/afm/map_indentation.csv");
    let text = std::fs::read_to_string(data).unwrap();
    assert!(text.contains("t [s],x [nm],f [nN]"));
    let robot = dir.path().join("map_robot.csv");
    std::fs::write(&robot, text.replace("t [s],x [nm],f [nN]", "t [s],x [µm],f [N]")).unwrap();
    let (afm, at_robot) = (report_of(dir.path(), data), report_of(dir.path(), robot.to_str().unwrap()));
    assert_eq!(ids(&afm), ids(&at_robot));
    assert!(!ids(&afm).is_empty());
    let closed = |v: &serde_json::Value| v["final_rms"].as_f64().unwrap() / v["baseline"]["rms"].as_f64().unwrap();
    assert!((closed(&afm) - closed(&at_robot)).abs() < 0.02, "{} against {}", closed(&afm), closed(&at_robot));
    assert!((at_robot["final_rms"].as_f64().unwrap() / afm["final_rms"].as_f64().unwrap() / 1e9 - 1.0).abs() < 0.02);
}

fn report_of(dir: &Path, path: &str) -> serde_json::Value {
    let json = dir.join("report.json");
    let run = discrepancy(&[path.as_ref(), "--out".as_ref(), dir.as_os_str(), "--json".as_ref(), json.as_os_str()]);
    assert!(run.status.success(), "{}", text(&run));
    serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap()
}

/// The drag [N·s/m] an AFM table's free levels show, worked out without the workflow: the mean force and
/// speed of the free samples on the approach and on the retract (those more than 30 % of the travel away
/// from the deepest point), and the levels' difference over the speeds' difference.
fn drag_from_free_levels(path: &str) -> f64 {
    let rows: Vec<[f64; 3]> = std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('t'))
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
            [v[0], v[1] * 1e-9, v[2] * 1e-9]
        })
        .collect();
    let n = rows.len();
    let w = (n / 100).max(5);
    let speed = |i: usize| {
        let (a, b) = (i.saturating_sub(w), (i + w).min(n - 1));
        (rows[b][1] - rows[a][1]) / (rows[b][0] - rows[a][0])
    };
    let deepest = (0..n).max_by(|&i, &j| rows[i][1].total_cmp(&rows[j][1])).unwrap();
    let shallowest = rows.iter().map(|r| r[1]).fold(f64::INFINITY, f64::min);
    let far = rows[deepest][1] - 0.3 * (rows[deepest][1] - shallowest);
    let level = |range: std::ops::Range<usize>| {
        let free: Vec<usize> = range.filter(|&i| rows[i][1] < far).collect();
        let mean = |x: &dyn Fn(usize) -> f64| free.iter().map(|&i| x(i)).sum::<f64>() / free.len() as f64;
        (mean(&|i| rows[i][2]), mean(&speed))
    };
    let ((f_in, v_in), (f_out, v_out)) = (level(0..deepest), level(deepest..n));
    (f_in - f_out) / (v_in - v_out)
}

/// A table from any instrument runs through identify and discrepancy with no flags, in its own units.
#[test]
fn a_table_runs_through_identify_and_discrepancy_with_no_flags() {
    let file = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/afm/qi_stiff_indentation.csv");
    let id = Command::new(env!("CARGO_BIN_EXE_softcontact")).args(["identify", file]).output().unwrap();
    let shown = text(&id);
    assert!(id.status.success(), "{shown}");
    assert!(shown.contains("force zeroed at its free level -175.") && shown.contains(" nN"), "{shown}");
    assert!(shown.contains("selected:"), "{shown}");
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("d.json");
    let run = discrepancy(&[
        std::ffi::OsStr::new(file),
        "--out".as_ref(),
        dir.path().as_os_str(),
        "--json".as_ref(),
        json.as_os_str(),
    ]);
    let shown = text(&run);
    assert!(run.status.success(), "{shown}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    // Scale-free: the noise floor of a 1 µN contact is a fraction of a nN, not the robot's floors.
    let sigma = v["noise_floor"].as_f64().unwrap();
    assert!(sigma > 1e-11 && sigma < 1e-8, "{sigma}");
    // The floor's line gives a tare's level σ only where it differs from the floor.
    let line = shown.lines().find(|l| l.starts_with("noise floor ")).unwrap_or_else(|| panic!("{shown}"));
    let floor = &line["noise floor ".len()..line.find(" (").unwrap()];
    assert_eq!(line.matches(floor).count(), 1, "{line}");
    let level = v["level_noise"].as_f64().unwrap();
    assert_eq!(line.contains("tare's window"), (level / sigma - 1.0).abs() > 0.01, "{line} ({level} vs {sigma})");
    assert!(v.get("overlay_file").is_none(), "a table's model is not the arm's: {v}");
    // A malformed cell is named by line and column.
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "t [s],x [nm],f [nN]\n0,1,2\n0.1,2,oops\n").unwrap();
    let id = Command::new(env!("CARGO_BIN_EXE_softcontact")).arg("identify").arg(&bad).output().unwrap();
    assert!(!id.status.success());
    assert!(text(&id).contains("line 3, column 3 (`f [nN]`): `oops` is not a number"), "{}", text(&id));
}

/// A testing machine's load–unload cycle at 50 Hz, written here (a Prony series of nine branches from
/// 0.1 to 1000 s, the specimen slack below zero force, AR(1) noise): a second at rest, 2 s stretched to
/// 5 mm, 2 s back, 6 s at rest. As exported with its crosshead's position (x, in mm; time in ms, force
/// in mN) the rest at the start is a pause whose zero is the instrument's (zeroed at the least force,
/// a noise extreme 8 mN down, a `sensor_bias` was named beside the relaxation); as a deformation (z) the
/// start at z ≤ 0 is its free level. Either way the relaxation alone is named, and the gap closes.
#[test]
fn a_testing_machines_load_unload_cycle_names_the_relaxation_alone_from_x_or_z() {
    let dir = tempfile::tempdir().unwrap();
    let (dt, taus) = (0.02, [0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0]);
    let weights = [1.0, 1.0, 1.0, 1.2, 1.0, 0.8, 0.6, 0.5, 0.4];
    let (mut branches, mut before, mut coloured, mut seed) = ([0.0f64; 9], 0.0, 0.0, 11u64);
    let mut uniform = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let rows: Vec<(f64, f64, f64)> = (0..650)
        .map(|k| {
            let t = k as f64 * dt - 1.0;
            let x = if t < 0.0 {
                0.0
            } else if t < 2.0 {
                2.5 * t
            } else if t < 4.0 {
                2.5 * (4.0 - t)
            } else {
                0.0
            };
            for ((s, tau), w) in branches.iter_mut().zip(taus).zip(weights) {
                let decay: f64 = (-dt / tau).exp();
                *s = *s * decay + w * (x - before) / dt * tau * (1.0 - decay);
            }
            before = x;
            coloured = 0.9 * coloured + 0.0052 * uniform();
            let force: f64 = 1.47 / 7.0 * (0.9 * x + branches.iter().sum::<f64>()) * 0.25;
            (t + 1.0, x, force.max(0.0) + coloured)
        })
        .collect();
    for (header, says) in [
        ("t [ms],x [mm],f [mN]", "its zero is the instrument's"),
        ("t [ms],z [mm],f [mN]", "force zeroed at its free level"),
    ] {
        let path = dir.path().join("cycle.csv");
        let body: String = rows.iter().map(|(t, x, f)| format!("{},{x},{}\n", t * 1e3, f * 1e3)).collect();
        std::fs::write(&path, format!("{header}\n{body}")).unwrap();
        let json = dir.path().join("cycle.json");
        let run = discrepancy(&[
            path.as_os_str(),
            "--out".as_ref(),
            dir.path().as_os_str(),
            "--json".as_ref(),
            json.as_os_str(),
        ]);
        let shown = text(&run);
        assert!(run.status.success() && shown.contains(says), "{header}: {shown}");
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        assert_eq!(ids(&v), vec!["viscoelastic_relaxation"], "{header}: {shown}");
        let (before, after) = (v["baseline"]["rms"].as_f64().unwrap(), v["final_rms"].as_f64().unwrap());
        assert!(after < 0.2 * before, "{header}: {before} → {after} N");
    }
}

/// A stress-relaxation test as a testing machine exports it (crosshead position x in mm, force in N, 50 Hz):
/// a second at rest, a 2 s ramp to 2 mm, a 30-minute hold; the force a Boltzmann superposition of a
/// relaxation function written here, not of the library's form: a power law G = 0.1 + 0.9 (1 + u/0.3 s)^−0.38
/// (1.47 N at the end of the ramp, 0.30 N at the end), with 0.5 µm of crosshead noise and coloured force
/// noise. Relaxation is named, nothing else, and it closes at least 30 % of the gap.
#[test]
fn a_testing_machines_stress_relaxation_of_a_power_law_is_named_as_relaxation_alone() {
    let dir = tempfile::tempdir().unwrap();
    let mut seed = 11u64;
    let mut gauss = move || {
        let mut uniform = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos()
    };
    let relaxation = |u: f64| 0.1 + 0.9 * (1.0 + u / 0.3).powf(-0.38);
    let (name, hold) = ("power", 1800.0);
    let fs = 50.0;
    let n = ((3.0 + hold) * fs) as usize + 1;
    let x = |t: f64| 2.0 * ((t - 1.0) / 2.0).clamp(0.0, 1.0);
    // The ramp as steps at mid-sample; the force at the end of the ramp scaled to 1.47 N.
    let steps: Vec<(f64, f64)> = (1..n)
        .map(|i| ((i as f64 - 0.5) / fs, x(i as f64 / fs) - x((i - 1) as f64 / fs)))
        .filter(|s| s.1 != 0.0)
        .collect();
    let force = |t: f64| steps.iter().filter(|s| t >= s.0).map(|s| relaxation(t - s.0) * s.1).sum::<f64>();
    let scale = 1.47 / force(3.0);
    let (mut red, mut body) = (0.0, String::new());
    for i in 0..n {
        let t = i as f64 / fs;
        red = 0.98 * red + 0.003 * (1.0f64 - 0.98 * 0.98).sqrt() * gauss();
        let f = scale * force(t) + red + 0.002 * gauss();
        body.push_str(&format!("{t:.2},{:.5},{f:.5}\n", x(t) + 0.0005 * gauss()));
    }
    let path = dir.path().join(format!("{name}.csv"));
    std::fs::write(&path, format!("t [s],x [mm],f [N]\n{body}")).unwrap();
    let json = dir.path().join(format!("{name}.json"));
    let run =
        discrepancy(&[path.as_os_str(), "--out".as_ref(), dir.path().as_os_str(), "--json".as_ref(), json.as_os_str()]);
    let shown = text(&run);
    assert!(run.status.success(), "{name}: {shown}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let named = ids(&v);
    assert!(named.iter().all(|id| id == "viscoelastic_relaxation"), "{name}: {named:?}\n{shown}");
    let (before, after) = (v["baseline"]["rms"].as_f64().unwrap(), v["final_rms"].as_f64().unwrap());
    assert!(!named.is_empty() && after < 0.7 * before, "{name}: {before} → {after} N\n{shown}");
}

/// Peak resident memory [bytes] of a finished child, from wait4's rusage (Linux reports KiB).
#[allow(clippy::zombie_processes, reason = "the child is reaped by wait4, which also gives its rusage")]
fn run_measuring_peak_memory(command: &mut Command) -> (std::process::ExitStatus, u64) {
    use std::os::unix::process::ExitStatusExt;
    let child = command.stdout(std::process::Stdio::null()).spawn().unwrap();
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: rusage is plain data, zeroed is a valid value; wait4 writes it and the status for our child.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let waited = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(waited, pid, "wait4: {}", std::io::Error::last_os_error());
    (std::process::ExitStatus::from_raw(status), usage.ru_maxrss as u64 * 1024)
}

#[test]
fn a_ten_million_row_table_runs_through_discrepancy_in_bounded_memory() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.csv");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    writeln!(file, "t [s],x [mm],f [N]").unwrap();
    // 1000 s at 10 kHz: fifty 20 s pushes to 4 mm into a Hertzian surface, from 2 mm above it, with a
    // deterministic ripple for noise.
    for i in 0..10_000_000u64 {
        let t = i as f64 * 1e-4;
        let x = -2.0 + 6.0 * (std::f64::consts::PI * (t % 20.0) / 20.0).sin().powi(2);
        let ripple = 0.05 * ((i * 2_654_435_761) % 1000) as f64 / 1000.0;
        writeln!(file, "{t:.4},{x:.5},{:.4}", 50.0 * x.max(0.0).powf(1.5) + ripple).unwrap();
    }
    file.flush().unwrap();
    drop(file);
    let (status, peak) = run_measuring_peak_memory(
        Command::new(env!("CARGO_BIN_EXE_softcontact")).arg("discrepancy").arg(&path).arg("--out").arg(dir.path()),
    );
    assert!(status.success(), "{status}");
    // A measurement, not a zero: the table alone is 255 MB, read in two streaming passes.
    assert!(peak > 4 << 20 && peak <= 512 << 20, "peak resident memory {} MiB", peak >> 20);
}

/// A parameter the record does not pin down is printed without a value in the text report, its interval
/// beside it; the JSON keeps value and interval, listing it under `not_identifiable`.
#[test]
fn the_text_report_gives_no_value_for_a_parameter_that_is_not_identifiable() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("report.json");
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/afm/flipsign_indentation.csv");
    let run =
        discrepancy(&[path.as_ref(), "--out".as_ref(), dir.path().as_os_str(), "--json".as_ref(), json.as_os_str()]);
    let shown = text(&run);
    assert!(run.status.success(), "{shown}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let mut checked = 0;
    for e in v["effects"].as_array().unwrap() {
        for k in e["not_identifiable"].as_array().unwrap().iter().map(|k| k.as_str().unwrap()) {
            assert!(e["parameters"][k].is_number() && e["uncertainty"][k].is_number(), "{e}");
            assert!(shown.contains(&format!("{k} not identifiable (± ")), "{k}\n{shown}");
            let value = format!("{k} {:.4e}", e["parameters"][k].as_f64().unwrap());
            assert!(!shown.contains(&value), "{value}\n{shown}");
            checked += 1;
        }
    }
    assert!(checked > 0, "flipsign's relaxation time is not pinned down by its 0.5 ms record\n{shown}");
}

/// A table of a medium more viscous than a plausible one (a Kelvin–Voigt surface of 5000 N/m under a
/// squeeze film of 80 N·s/m reaching 5 mm and a drag of 40, 120 in all): the augmented model written
/// keeps the medium within the bound (`MAX_MEDIUM_DRAG`, 100 N·s/m), so that the nodes take it.
#[test]
fn a_table_of_a_medium_beyond_the_bound_gives_a_model_within_it() {
    use rand::{SeedableRng, rngs::SmallRng};
    use rand_distr::{Distribution, Normal};
    let dir = tempfile::tempdir().unwrap();
    let mut x = vec![-0.03; 1000];
    for v in [0.01, 0.03, 0.02, 0.05] {
        let n = (0.04 / v / 1e-3) as usize;
        x.extend((0..n).map(|i| -0.03 + 0.04 * i as f64 / n as f64));
        x.extend([0.01; 500]);
        x.extend((0..n).map(|i| 0.01 - 0.04 * i as f64 / n as f64));
        x.extend([-0.03; 500]);
    }
    let (mut rng, noise) = (SmallRng::seed_from_u64(1), Normal::new(0.0, 0.01).unwrap());
    let mut table = String::from("t [s],x [m],f [N]\n");
    for i in 0..x.len() {
        let (a, b) = (i.saturating_sub(1), (i + 1).min(x.len() - 1));
        let rate = (x[b] - x[a]) / ((b - a) as f64 * 1e-3);
        let film = 80.0 * 5e-3 / ((-x[i]).max(0.0) + 5e-3);
        let f = 5000.0 * x[i].max(0.0) + (film + 40.0) * rate + noise.sample(&mut rng);
        table += &format!("{:.6},{:.9},{f:.6}\n", i as f64 * 1e-3, x[i]);
    }
    let path = dir.path().join("viscous.csv");
    std::fs::write(&path, table).unwrap();
    let v = report_of(dir.path(), path.to_str().unwrap());
    let drags: f64 = v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["id"] == "medium_drag" || e["id"] == "squeeze_film")
        .map(|e| e["parameters"]["damping_n_s_per_m"].as_f64().unwrap())
        .sum();
    assert!(drags > 0.0 && drags <= 100.0, "{drags} N·s/m named: {}", v["effects"]);
}

/// The augmented model of a table names the surface it was fitted at; given back with `--model` and that
/// `--surface`, it starts where its fit ended: its residual as the baseline is the first run's final one.
/// A surface that is no length is refused, naming the units.
#[test]
fn a_tables_augmented_model_given_back_at_its_surface_starts_from_its_own_fit() {
    let dir = tempfile::tempdir().unwrap();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/afm/map_indentation.csv");
    let first = report_of(dir.path(), data);
    let model = dir.path().join("map_indentation.augmented.yaml");
    let file = std::fs::read_to_string(&model).unwrap();
    let surface = file.lines().find_map(|l| l.split("--surface ").nth(1)).expect("the surface in the file").trim();
    assert!(ContactModel::from_yaml(&file).is_ok(), "the file with its comment is a model");
    let again = dir.path().join("again");
    let json = again.join("report.json");
    let args = [data.as_ref(), "--model".as_ref(), model.as_os_str(), "--surface".as_ref(), surface.as_ref()];
    let run =
        discrepancy(&[&args[..], &["--out".as_ref(), again.as_os_str(), "--json".as_ref(), json.as_os_str()]].concat());
    assert!(run.status.success(), "{}", text(&run));
    assert!(text(&run).contains("the given model's effects (adhesion"), "{}", text(&run));
    let second: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let (before, after) = (second["baseline"]["rms"].as_f64().unwrap(), first["final_rms"].as_f64().unwrap());
    assert!((before / after - 1.0).abs() < 0.01, "given back at its surface {before}, its fit ended at {after}");
    // Refitted from its law alone, the workflow fits free space better and this contact worse: the model as
    // given stands, never worse in contact than it was.
    let last = second["final_rms"].as_f64().unwrap();
    assert!(last <= before, "ended at {last}, worse than the {before} given");
    // The final law is printed as the file holds it.
    let written = std::fs::read_to_string(again.join("map_indentation.augmented.yaml")).unwrap();
    let written = ContactModel::from_yaml(&written).unwrap();
    let law = text(&run).lines().find_map(|l| l.strip_prefix("its law: ").map(str::to_string)).expect("its law");
    let k: f64 = law.split("k = ").nth(1).and_then(|r| r.split(',').next()).unwrap().parse().unwrap();
    assert!(law.starts_with(written.kind.id()) && (k / written.stiffness - 1.0).abs() < 1e-4, "{law}: {written:?}");
    let bad = discrepancy(&[data.as_ref(), "--surface".as_ref(), "3 furlongs".as_ref()]);
    assert!(!bad.status.success() && text(&bad).contains("nm"), "{}", text(&bad));
}

/// A relaxation far slower than the recording ends at the top of the time constants screened: the text
/// says it is a bound with the range's end, as the JSON's `bounds` has it, and names nothing of it.
#[test]
fn a_shape_at_the_end_of_its_range_is_said_to_be_a_bound_not_named() {
    let dir = tempfile::tempdir().unwrap();
    let mut slow = ContactModel::new(Kind::AzadFeatherstone, 25_000.0, 1100.0).unwrap();
    slow.effects.push(Effect::ViscoelasticRelaxation { stiffness: 3000.0, time_constant: 250.0 });
    let (report, _, shown) = analyse(dir.path(), "slow", &slow);
    let bounds = report["bounds"].as_array().unwrap();
    assert!(!bounds.is_empty(), "no bound: {shown}");
    for b in bounds {
        let id = b["id"].as_str().unwrap();
        assert!(shown.contains(&format!("not named: {id} at ")), "{id} not said: {shown}");
        assert!(!ids(&report).iter().any(|n| n == id), "{id} named: {shown}");
    }
    assert!(shown.contains("(a bound, not a finding)"), "{shown}");
}

/// A surface stiffer than the controller takes: the command says it writes no parameters for the graph
/// and still writes the report, the model file and the figures.
#[test]
fn a_model_the_controller_refuses_gets_no_overlay_and_loses_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let stiff = ContactModel::new(Kind::AzadFeatherstone, 3.0e6, 1100.0).unwrap();
    assert!(stiff.plausible().is_err(), "the test needs a model the controller refuses");
    // An earlier run's overlay in the same folder goes: it is not of this recording.
    let stale = dir.path().join("out").join("stiff.params.yaml");
    std::fs::create_dir_all(stale.parent().unwrap()).unwrap();
    std::fs::write(&stale, "deformation_controller: {}\n").unwrap();
    let (report, augmented, shown) = analyse(dir.path(), "stiff", &stiff);
    assert!(shown.contains("an earlier run's parameters for the graph"), "{shown}");
    assert!(augmented.plausible().is_err(), "{shown}");
    assert!(
        shown.contains("no parameters for the graph: the augmented model is not one the controller takes"),
        "{shown}"
    );
    assert!(report.get("overlay_file").is_none(), "{report}");
    let out = dir.path().join("out");
    for file in ["stiff.augmented.yaml", "stiff.residual.svg", "stiff.loops.svg", "stiff.residual.csv"] {
        assert!(out.join(file).exists(), "{file} missing: {shown}");
    }
    assert!(!out.join("stiff.params.yaml").exists(), "{shown}");
}

/// A nanoindenter's text export as its software saved it (`data/exports`: 36 lines of settings with a
/// Latin-1 µ, CRLF line endings, `Time (s)  Load (uN)  Indentation (nm) …`): read with no flags and no
/// editing, and no final model worse than the one identified.
#[test]
fn a_nanoindenters_own_export_runs_as_saved() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("chiaro.json");
    let file = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/exports/chiaro_indentation.txt");
    let out = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["discrepancy", file, "--out"])
        .arg(dir.path())
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    let shown = text(&out);
    assert!(out.status.success(), "{shown}");
    assert!(shown.contains("1383 rows") && shown.contains("depth as deformation (z)"), "{shown}");
    assert!(shown.contains("the header is line 37: the 36 lines before it are read as the instrument's preamble"));
    assert!(shown.contains("columns not read: Cantilever (nm), Piezo (nm), Auxiliary"), "{shown}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let (baseline, last) = (v["baseline"]["rms"].as_f64().unwrap(), v["final_rms"].as_f64().unwrap());
    // The load peaks at 48 nN: its residual is in nN, read from µN.
    assert!(last <= baseline && baseline > 1e-9 && baseline < 1e-8, "{baseline} → {last}");
}
