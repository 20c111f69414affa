//! The planar floating-base chain against Pinocchio, live: the same chain built from Pinocchio's PX, PY
//! and RZ joints (tests/planar_pinocchio.py) gives M, the nonlinear effects and every node's position and
//! Jacobian for 50 random states; they agree to 1e-10 relative. The interpreter is `$SOFTCONTACT_PYTHON`,
//! else `python3`.

use std::io::Write;
use std::process::{Command, Stdio};

use rand::{Rng, SeedableRng};
use serde::Deserialize;
use softcontact_dynamics::{PlanarChain, PlanarLink};

#[derive(Deserialize)]
struct Reference {
    mass_matrix: Vec<Vec<f64>>,
    nonlinear_effects: Vec<f64>,
    nodes: Vec<Vec<f64>>,
    jacobians: Vec<Vec<Vec<f64>>>,
}

#[derive(Deserialize)]
struct Output {
    pinocchio: String,
    states: Vec<Reference>,
}

fn close(a: f64, b: f64, scale: f64) -> bool {
    (a - b).abs() <= 1e-10 * scale.max(1.0)
}

#[test]
fn the_planar_chain_matches_pinocchio() {
    let mut chain = PlanarChain::uniform(4, 0.1, 0.2);
    chain.links[1] = PlanarLink { length: 0.12, mass: 0.25, com: 0.07, inertia: 4e-4 };
    chain.links[3].com = 0.03;
    let mut rng = rand::rngs::SmallRng::seed_from_u64(3);
    let states: Vec<(Vec<f64>, Vec<f64>)> = (0..50)
        .map(|_| {
            let q = (0..chain.dof()).map(|_| rng.random_range(-3.0..3.0)).collect();
            let dq = (0..chain.dof()).map(|_| rng.random_range(-5.0..5.0)).collect();
            (q, dq)
        })
        .collect();
    let spec = serde_json::json!({
        "gravity": chain.gravity,
        "links": chain.links.iter().map(|l| serde_json::json!({
            "length": l.length, "mass": l.mass, "com": l.com, "inertia": l.inertia,
        })).collect::<Vec<_>>(),
        "states": states.iter().map(|(q, dq)| serde_json::json!({"q": q, "dq": dq})).collect::<Vec<_>>(),
    });
    let python = std::env::var("SOFTCONTACT_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/planar_pinocchio.py");
    let mut child = Command::new(&python)
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run {python}: {e}"));
    child.stdin.take().unwrap().write_all(spec.to_string().as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{script} failed; Pinocchio is needed: pip install pin");
    let reference: Output = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("Pinocchio {}", reference.pinocchio);
    for ((q, dq), r) in states.iter().zip(&reference.states) {
        let m = chain.mass_matrix(q);
        let scale = m.amax();
        for (i, row) in r.mass_matrix.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!(close(m[(i, j)], *v, scale), "M[{i},{j}] {} vs {v} at q {q:?}", m[(i, j)]);
            }
        }
        let h = chain.nonlinear_effects(q, dq);
        let scale = r.nonlinear_effects.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for (i, v) in r.nonlinear_effects.iter().enumerate() {
            assert!(close(h[i], *v, scale), "h[{i}] {} vs {v} at q {q:?}, dq {dq:?}", h[i]);
        }
        let nodes = chain.node_positions(q);
        for (k, (p, j)) in r.nodes.iter().zip(&r.jacobians).enumerate() {
            assert!(close(nodes[k].x, p[0], 1.0) && close(nodes[k].y, p[1], 1.0), "node {k}");
            let (link, along) = if k == 0 { (0, 0.0) } else { (k - 1, chain.links[k - 1].length) };
            let ours = chain.point_jacobian(q, link, along);
            for (row, values) in j.iter().enumerate() {
                for (col, v) in values.iter().enumerate() {
                    assert!(close(ours[(row, col)], *v, 1.0), "node {k} J[{row},{col}] {} vs {v}", ours[(row, col)]);
                }
            }
        }
    }
}
