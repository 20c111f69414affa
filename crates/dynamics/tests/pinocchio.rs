//! The dynamics against Pinocchio, live: every run regenerates reference values with Pinocchio's Python
//! bindings (`pip install pin`) for 200 random states on urdf/lwr4.urdf and compares them to 1e-9
//! relative (infinity norm of the difference over that of the reference, floored at 1).
//!
//! The interpreter is `$SOFTCONTACT_PYTHON`, else `python3`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

use nalgebra::{DMatrix, Matrix6xX, Vector3};
use serde::Deserialize;
use softcontact_dynamics::{Axes, ExternalWrench, Model};

const TOLERANCE: f64 = 1e-9;

#[derive(Deserialize)]
struct Placement {
    translation: Vec<f64>,
    rotation: Vec<Vec<f64>>,
}

#[derive(Deserialize)]
struct State {
    q: Vec<f64>,
    dq: Vec<f64>,
    ddq: Vec<f64>,
    tau: Vec<f64>,
    force: Vec<f64>,
    torque: Vec<f64>,
    frames: HashMap<String, Placement>,
    jacobian_world: HashMap<String, Vec<Vec<f64>>>,
    jacobian_local: HashMap<String, Vec<Vec<f64>>>,
    tool_bias_acceleration: Vec<f64>,
    rnea: Vec<f64>,
    rnea_external: Vec<f64>,
    mass_matrix: Vec<Vec<f64>>,
    gravity: Vec<f64>,
    nonlinear_effects: Vec<f64>,
    aba: Vec<f64>,
    aba_external: Vec<f64>,
    kinetic_energy: f64,
    potential_energy: f64,
}

#[derive(Deserialize)]
struct Fixtures {
    pinocchio: String,
    tool: String,
    states: Vec<State>,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Generates the fixtures once per test binary.
fn fixtures() -> &'static Fixtures {
    static FIXTURES: OnceLock<Fixtures> = OnceLock::new();
    FIXTURES.get_or_init(|| {
        let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("pinocchio_fixtures.json");
        let python = std::env::var("SOFTCONTACT_PYTHON").unwrap_or_else(|_| "python3".into());
        let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/pinocchio_fixtures.py");
        let status = Command::new(&python)
            .arg(&script)
            .arg(root().join("urdf/lwr4.urdf"))
            .arg(&out)
            .args(["--states", "200"])
            .status()
            .unwrap_or_else(|e| panic!("cannot run {python}: {e}"));
        assert!(status.success(), "{} failed; Pinocchio is needed: pip install pin", script.display());
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap()
    })
}

fn model() -> Model {
    Model::from_urdf_file(root().join("urdf/lwr4.urdf")).unwrap()
}

fn assert_close(what: &str, state: usize, ours: &[f64], reference: &[f64]) {
    assert_eq!(ours.len(), reference.len(), "{what}: length");
    let scale = reference.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let err = ours.iter().zip(reference).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        err <= TOLERANCE * scale,
        "{what}, state {state}: max difference {err:e} (scale {scale})\n ours {ours:?}\n pin  {reference:?}"
    );
}

fn rows(m: &[Vec<f64>]) -> Vec<f64> {
    m.iter().flatten().copied().collect()
}

fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

#[test]
fn fixtures_cover_enough_states() {
    let f = fixtures();
    assert!(f.states.len() >= 200);
    eprintln!("Pinocchio {}", f.pinocchio);
}

#[test]
fn frame_placements_match() {
    let (model, mut data) = {
        let m = model();
        let d = m.data();
        (m, d)
    };
    for (k, s) in fixtures().states.iter().enumerate() {
        model.forward_kinematics(&mut data, &s.q);
        assert_eq!(
            s.frames.len(),
            model.frames.len() - usize::from(model.frame_id("world").is_ok() && !s.frames.contains_key("world"))
        );
        for (name, p) in &s.frames {
            let pose = model.frame_pose(&data, model.frame_id(name).unwrap());
            assert_close(&format!("{name} translation"), k, pose.translation.vector.as_slice(), &p.translation);
            let r = pose.rotation.to_rotation_matrix().into_inner();
            assert_close(
                &format!("{name} rotation"),
                k,
                &row_major(&DMatrix::from_column_slice(3, 3, r.as_slice())),
                &rows(&p.rotation),
            );
        }
    }
}

#[test]
fn jacobians_match() {
    let model = model();
    let mut data = model.data();
    let mut j = Matrix6xX::zeros(model.dof());
    for (k, s) in fixtures().states.iter().enumerate() {
        model.forward_kinematics(&mut data, &s.q);
        for (axes, reference) in [(Axes::World, &s.jacobian_world), (Axes::Local, &s.jacobian_local)] {
            for (name, jr) in reference {
                model.frame_jacobian(&data, model.frame_id(name).unwrap(), axes, &mut j);
                let ours = row_major(&DMatrix::from_column_slice(6, model.dof(), j.as_slice()));
                assert_close(&format!("{name} Jacobian {axes:?}"), k, &ours, &rows(jr));
            }
        }
    }
}

#[test]
fn bias_acceleration_matches() {
    let model = model();
    let mut data = model.data();
    let tool = model.frame_id(&fixtures().tool).unwrap();
    for (k, s) in fixtures().states.iter().enumerate() {
        let b = model.frame_bias_acceleration(&mut data, &s.q, &s.dq, tool);
        assert_close("J̇q̇", k, b.as_slice(), &s.tool_bias_acceleration);
    }
}

#[test]
fn inverse_dynamics_matches() {
    let model = model();
    let mut data = model.data();
    let tool = model.frame_id(&fixtures().tool).unwrap();
    for (k, s) in fixtures().states.iter().enumerate() {
        assert_close("rnea", k, model.rnea(&mut data, &s.q, &s.dq, &s.ddq, None).as_slice(), &s.rnea);
        let w = ExternalWrench {
            frame: tool,
            force: Vector3::from_column_slice(&s.force),
            torque: Vector3::from_column_slice(&s.torque),
        };
        assert_close(
            "rnea with external wrench",
            k,
            model.rnea(&mut data, &s.q, &s.dq, &s.ddq, Some(&w)).as_slice(),
            &s.rnea_external,
        );
        assert_close("gravity", k, model.gravity_torques(&mut data, &s.q).as_slice(), &s.gravity);
        assert_close(
            "nonlinear effects",
            k,
            model.nonlinear_effects(&mut data, &s.q, &s.dq).as_slice(),
            &s.nonlinear_effects,
        );
    }
}

#[test]
fn mass_matrix_and_forward_dynamics_match() {
    let model = model();
    let mut data = model.data();
    let tool = model.frame_id(&fixtures().tool).unwrap();
    for (k, s) in fixtures().states.iter().enumerate() {
        assert_close("mass matrix", k, &row_major(model.mass_matrix(&mut data, &s.q)), &rows(&s.mass_matrix));
        assert_close(
            "aba",
            k,
            model.forward_dynamics(&mut data, &s.q, &s.dq, &s.tau, None).unwrap().as_slice(),
            &s.aba,
        );
        let w = ExternalWrench {
            frame: tool,
            force: Vector3::from_column_slice(&s.force),
            torque: Vector3::from_column_slice(&s.torque),
        };
        assert_close(
            "aba with external wrench",
            k,
            model.forward_dynamics(&mut data, &s.q, &s.dq, &s.tau, Some(&w)).unwrap().as_slice(),
            &s.aba_external,
        );
    }
}

#[test]
fn energies_match() {
    let model = model();
    let mut data = model.data();
    for (k, s) in fixtures().states.iter().enumerate() {
        assert_close("kinetic energy", k, &[model.kinetic_energy(&mut data, &s.q, &s.dq)], &[s.kinetic_energy]);
        assert_close("potential energy", k, &[model.potential_energy(&mut data, &s.q)], &[s.potential_energy]);
    }
}

#[test]
fn control_terms_match() {
    let model = model();
    let mut data = model.data();
    let tool = model.frame_id(&fixtures().tool).unwrap();
    for (k, s) in fixtures().states.iter().enumerate() {
        let t = model.control_terms(&mut data, &s.q, &s.dq, tool).unwrap();
        let j = row_major(&DMatrix::from_column_slice(6, model.dof(), t.jacobian.as_slice()));
        assert_close("tick Jacobian", k, &j, &rows(&s.jacobian_world[&fixtures().tool]));
        assert_close("tick J̇q̇", k, t.bias_acceleration.as_slice(), &s.tool_bias_acceleration);
        assert_close("tick M", k, &row_major(t.mass_matrix), &rows(&s.mass_matrix));
        assert_close("tick h", k, t.nonlinear_effects.as_slice(), &s.nonlinear_effects);
        let m = DMatrix::from_row_slice(7, 7, &rows(&s.mass_matrix));
        let identity = t.mass_matrix_inverse * m;
        assert_close("tick M⁻¹ M", k, identity.as_slice(), DMatrix::<f64>::identity(7, 7).as_slice());
    }
}
