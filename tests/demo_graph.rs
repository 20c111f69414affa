//! `softcontact demo --graph`, shortened (12 s of identification pushes and three force commands per
//! surface): the node processes come up in a loopback-only namespace for each surface, the demo client
//! drives them over DDS in real time, and the tables, the JSON and a recording per surface come out;
//! then the discrepancy workflow runs on each recording and a second graph, started with the augmented
//! model's parameter overlay, takes the three commands again. The same with `--secure`: every graph under
//! ROS 2 security, the client in `/user`'s enclave (needs the `security` feature).

use std::process::Command;

#[test]
fn the_graph_demo_runs_the_node_processes_for_both_surfaces_and_again_through_the_augmented_model() {
    graph_demo(&[]);
}

#[test]
#[cfg_attr(not(feature = "security"), ignore = "needs the `security` feature")]
fn the_graph_demo_runs_as_well_on_graphs_under_ros_2_security() {
    graph_demo(&["--secure"]);
}

/// One graph demo at a time: each runs in real time, and two at once on a small machine miss their goals.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn graph_demo(extra: &[&str]) {
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    let out =
        std::env::temp_dir().join(format!("softcontact-demo-graph-test-{}{}", std::process::id(), extra.concat()));
    let _ = std::fs::remove_dir_all(&out);
    let json = out.join("demo.json");
    let run = Command::new(env!("CARGO_BIN_EXE_softcontact"))
        .args(["demo", "--graph", "--runs", "2", "--commands", "3"])
        .args(extra)
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .arg(&json)
        .env("SOFTCONTACT_BIN", std::path::Path::new(env!("CARGO_BIN_EXE_softcontact")).parent().unwrap())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&run.stdout);
    eprintln!("{text}{}", String::from_utf8_lossy(&run.stderr));
    assert!(run.status.success(), "the graph demo ran (logs in {})", out.join("graph_logs").display());
    assert!(text.contains("TABLE I") && text.contains("over DDS in real time"), "tables labelled as the graph run");
    if extra.contains(&"--secure") {
        let launched = format!("{text}{}", String::from_utf8_lossy(&run.stderr));
        assert_eq!(launched.matches("launch: secure: keystore").count(), 4, "four graphs, each under security");
    }

    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["mode"], "graph");
    for (s, name) in report["surfaces"].as_array().unwrap().iter().zip(["sponge", "dice"]) {
        assert_eq!(s["name"], name);
        assert_eq!(s["fitness"].as_object().unwrap().len(), 3, "{name}: three kinds scored");
        let max_force = s["max_force"].as_f64().unwrap();
        let commands = s["commands"].as_array().unwrap();
        assert_eq!(commands.len(), 6, "{name}: three commands through each model");
        // The augmented graph starts from the overlay's model; its estimator refits the named structure
        // online and the controller adopts a refit at the next command (the force-control paper's cycle).
        let overlay_stiffness = s["discrepancy"]["augmented_model"]["stiffness"].as_f64().unwrap();
        // Largest error through the identified model and through the overlay's model as given.
        let mut largest = [0.0_f64; 2];
        for (i, c) in commands.iter().enumerate() {
            let (model, ratio) = (["identified", "augmented"][i / 3], [0.8, 0.4, 0.7][i % 3]);
            assert_eq!(c["model"], model);
            let command = c["command"].as_f64().unwrap();
            assert!((command - ratio * max_force).abs() < 1e-9);
            // Graded on the simulator's true contact force (/sim_arm/contact_wrench); the sensor's beside.
            let (reached, measured) = (c["reached"].as_f64().unwrap(), c["reached_measured"].as_f64().unwrap());
            assert!((reached - measured).abs() < 1.0, "{name}: truth {reached} N, the sensor read {measured} N");
            let error = c["error"].as_f64().unwrap() / command * 100.0;
            let through_overlay = model == "augmented"
                && (c["model_stiffness"].as_f64().unwrap() - overlay_stiffness).abs() <= 1e-9 * overlay_stiffness;
            if model == "augmented" && i % 3 == 0 {
                assert!(
                    through_overlay,
                    "{name}: the augmented graph's first command goes through the overlay's model"
                );
            }
            // Through the model of the identification pushes, or a refit the estimator made online from a
            // few seconds of a real-time graph under load: the force-control paper's goal, 10 %. Through the
            // model the discrepancy workflow augmented from the first graph's recording, as given: 2 %.
            let goal = if through_overlay { 2.0 } else { 10.0 };
            let what = if through_overlay { "the overlay's" } else { model };
            assert!(error < goal, "{name}: {command:.1} N through {what} model within {goal} % ({error:.2} %)");
            if model == "identified" || through_overlay {
                largest[i / 3] = largest[i / 3].max(error);
            }
        }
        // The workflow's model against the identified one; a refit the estimator made online from a few
        // seconds under load is held to the paper's goal above, not to the workflow's.
        assert!(
            largest[1] < largest[0],
            "{name}: the overlay's largest error {:.2} % below the identified graph's {:.2} %",
            largest[1],
            largest[0]
        );
        // What the workflow named on the first graph's recording: the relaxation the surface hides.
        let named: Vec<&str> =
            s["discrepancy"]["named"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
        assert!(named.contains(&"viscoelastic_relaxation"), "{name}: named {named:?}");
        let overlay = out.join("graph_logs").join(name).join(format!("{name}.params.yaml"));
        assert!(std::fs::read_to_string(&overlay).unwrap().contains("initial_surface"), "{}", overlay.display());
        let rec = softcontact_bag::Recording::open(&out.join(format!("{name}_graph.mcap"))).unwrap();
        assert!(rec.topic("/ft_sensor/wrench").is_some_and(|t| t.message_count > 10_000), "{name}: recorded");
    }
    let _ = std::fs::remove_dir_all(&out);
}
