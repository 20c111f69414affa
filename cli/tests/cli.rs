//! The `softcontact` command as a user meets it.

use std::path::PathBuf;
use std::process::{Command, Output};

fn softcontact(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_softcontact")).args(args).output().expect("softcontact runs")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn help_lists_every_contract_command() {
    let o = softcontact(&["--help"]);
    assert!(o.status.success());
    for cmd in ["demo", "identify", "discrepancy", "record", "replay", "model", "bench"] {
        assert!(text(&o).contains(cmd), "--help should list `{cmd}`");
    }
    let o = softcontact(&["--version"]);
    assert!(o.status.success() && text(&o).contains(env!("CARGO_PKG_VERSION")));
}

#[test]
fn discrepancy_of_a_missing_file_says_so_and_fails() {
    let o = softcontact(&["discrepancy", "x.mcap"]);
    assert!(!o.status.success() && text(&o).contains("x.mcap") && !text(&o).contains("panicked"), "{}", text(&o));
}

#[test]
fn recording_commands_refuse_bad_arguments_before_touching_the_network() {
    let cases: [(&[&str], &str); 5] = [
        (
            &["record", "/lwr/not_a_topic"],
            "is not a topic of the graph; give its type as /lwr/not_a_topic:pkg/msg/Type",
        ),
        (&["record", "/x:foo_msgs/msg/Bar"], "type foo_msgs/msg/Bar is not one the project knows"),
        (&["record", "lwr/ee_pose"], "names start with /"),
        (&["replay", "/nonexistent/run.mcap"], "/nonexistent/run.mcap: No such file"),
        (&["replay", "x.mcap", "--rate", "0"], "--rate must be between 0.01 and 100"),
    ];
    for (args, want) in cases {
        let o = softcontact(args);
        assert!(!o.status.success() && text(&o).contains(want), "{args:?}: {}", text(&o));
    }
    // A missing file is said once, not again as the cause of itself.
    for args in [&["replay", "/nonexistent/run.mcap"][..], &["discrepancy", "/nonexistent/table.csv"]] {
        let o = softcontact(args);
        assert_eq!(text(&o).matches("No such file").count(), 1, "{args:?}: {}", text(&o));
    }
}

#[test]
fn demo_runs() {
    // Its outputs in a temporary folder, not in the source tree.
    let dir = tempfile::tempdir().unwrap();
    let o = softcontact(&["demo", "--out", dir.path().to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn model_rejects_bad_input() {
    for (args, words) in [
        (&["model", "--q", "0,1"][..], "has 2 values, the robot has 7 joints"),
        (&["model", "--q", "0,0,0,0,0,0,NaN"], "finite number"),
        (&["model", "--frame", "nowhere"], "no frame named `nowhere`"),
        (&["model", "--urdf", "/nonexistent.urdf"], "cannot read URDF"),
        (&["model", "--q", "0,a,0,0,0,0,0"], "invalid"),
    ] {
        let o = softcontact(args);
        assert!(!o.status.success(), "{args:?} must fail");
        assert!(text(&o).contains(words), "{args:?}: expected `{words}` in:\n{}", text(&o));
    }
}

/// What `softcontact model` prints as JSON is what Pinocchio computes on the same URDF and state.
#[test]
fn model_json_agrees_with_pinocchio() {
    let json = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("model.json");
    let urdf = root().join("urdf/lwr4.urdf");
    let o = softcontact(&[
        "model",
        "--urdf",
        urdf.to_str().unwrap(),
        "--q",
        "0.3,-1.1,0.5,1.7,-0.4,0.9,2.1",
        "--dq",
        "-0.5,0.2,1.0,-1.3,0.7,0.1,-2.0",
        "--ddq",
        "1,-2,3,-1,0.5,2,-3",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let value: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for key in ["joints", "frames", "jacobian", "mass_matrix", "gravity", "rnea"] {
        assert!(value.get(key).is_some(), "JSON key `{key}` missing");
    }
    assert_eq!(value["jacobian"].as_array().unwrap().len(), 6);
    let python = std::env::var("SOFTCONTACT_PYTHON").unwrap_or_else(|_| "python3".into());
    let check = Command::new(&python)
        .arg(root().join("cli/tests/model_vs_pinocchio.py"))
        .arg(&urdf)
        .arg(&json)
        .output()
        .expect("python runs");
    assert!(check.status.success(), "Pinocchio disagrees (pip install pin):\n{}", text(&check));
}

/// `softcontact climb`: the snake climbs with every set point sound, the JSON carries the contact forces
/// of every set point in the order of the feet as [fₙ ≥ 0, fₜ], the law-and-damping comparison has its
/// four rows, the set points chosen badly are judged not sound with reasons, and the figure is written.
#[test]
fn climb_climbs_and_writes_its_tables() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("climb.json");
    let o = softcontact(&[
        "climb",
        "--height",
        "0.008",
        "--out",
        dir.path().to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("SUCCESS"), "{}", text(&o));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let set_points = v["climb"]["set_points"].as_array().unwrap();
    assert!(set_points.len() >= 15);
    for sp in set_points {
        assert_eq!(sp["sound"], true, "{}", sp["name"]);
        let forces = sp["contact_forces"].as_array().unwrap();
        assert_eq!(forces.len(), 7, "one [fn, ft] per foot of the 6-link snake");
        let pressed: Vec<u64> = sp["pressed"].as_array().unwrap().iter().map(|p| p.as_u64().unwrap()).collect();
        assert!(pressed.len() >= 3);
        for (i, f) in forces.iter().enumerate() {
            let (n, t) = (f[0].as_f64().unwrap(), f[1].as_f64().unwrap());
            assert!(n >= 0.0 && t.is_finite());
            assert_eq!(n > 0.0, pressed.contains(&(i as u64)), "{}: foot {i} touches exactly when pressed", sp["name"]);
        }
        assert!(sp["stability"]["slowest"][0].as_f64().unwrap() < -1e-3);
    }
    assert!(v["climb"]["climbed"].as_f64().unwrap() >= 0.008);
    assert_eq!(v["variants"].as_array().unwrap().len(), 4);
    for bad in v["bad_set_points"].as_array().unwrap() {
        assert_eq!(bad["sound"], false, "{}", bad["what"]);
        assert!(!bad["faults"].as_array().unwrap().is_empty());
    }
    let svg = std::fs::read_to_string(dir.path().join("climb.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("<circle"));
}

#[test]
fn climb_refuses_a_snake_it_cannot_build() {
    for args in [&["climb", "--links", "4"][..], &["climb", "--height", "nan"], &["climb", "--step", "-1"]] {
        let o = softcontact(args);
        assert!(!o.status.success(), "{args:?}");
        assert!(text(&o).to_lowercase().contains("climb") || text(&o).contains("must"), "{}", text(&o));
    }
}
