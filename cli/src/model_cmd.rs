//! `softcontact model`: what a user checks first on a new robot description, printed and as JSON, so
//! that it can be compared with any other tool.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, bail};
use nalgebra::{DMatrix, Matrix6xX};
use serde::Serialize;
use softcontact_dynamics::{Axes, Model, lwr4};

#[derive(clap::Args)]
pub struct ModelArgs {
    /// URDF of the robot (default: the built-in KUKA LWR IV, urdf/lwr4.urdf).
    #[arg(long)]
    urdf: Option<PathBuf>,
    /// Joint positions (rad), comma-separated (default: zeros).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::ranges::real(-10.0, 10.0, " rad"))]
    q: Option<Vec<f64>>,
    /// Joint velocities [rad/s], comma-separated (default: zeros).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::ranges::real(-100.0, 100.0, " rad/s"))]
    dq: Option<Vec<f64>>,
    /// Joint accelerations [rad/s²], comma-separated (default: zeros).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::ranges::real(-1e4, 1e4, " rad/s²"))]
    ddq: Option<Vec<f64>>,
    /// Frame whose Jacobian is shown (default: lwr_tool if the robot has it, else the chain's last frame).
    #[arg(long)]
    frame: Option<String>,
    /// Write the description and the state's terms as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(Serialize)]
struct JointJson {
    name: String,
    lower: f64,
    upper: f64,
    velocity: f64,
    effort: f64,
}

#[derive(Serialize)]
struct BodyJson {
    joint: String,
    mass: f64,
    com: [f64; 3],
}

#[derive(Serialize)]
struct FrameJson {
    translation: [f64; 3],
    rotation: [[f64; 3]; 3],
}

/// The JSON of `softcontact model` (docs/contracts.md: stable keys, SI units, world frame).
#[derive(Serialize)]
struct ModelJson {
    robot: String,
    q: Vec<f64>,
    dq: Vec<f64>,
    ddq: Vec<f64>,
    joints: Vec<JointJson>,
    bodies: Vec<BodyJson>,
    frames: BTreeMap<String, FrameJson>,
    jacobian_frame: String,
    jacobian: Vec<Vec<f64>>,
    mass_matrix: Vec<Vec<f64>>,
    gravity: Vec<f64>,
    rnea: Vec<f64>,
}

fn state_vector(name: &str, given: Option<Vec<f64>>, n: usize) -> anyhow::Result<Vec<f64>> {
    let v = given.unwrap_or_else(|| vec![0.0; n]);
    if v.len() != n {
        bail!("--{name} has {} values, the robot has {n} joints", v.len());
    }
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        bail!("--{name} holds a non-finite value ({bad})");
    }
    Ok(v)
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

fn print_matrix(title: &str, m: &DMatrix<f64>) {
    println!("{title}");
    for r in m.row_iter() {
        println!("  {}", r.iter().map(|x| format!("{x:>10.4}")).collect::<Vec<_>>().join(" "));
    }
}

pub fn run(args: ModelArgs) -> anyhow::Result<()> {
    let model = match &args.urdf {
        Some(path) => Model::from_urdf_file(path)?,
        None => lwr4::model(),
    };
    let n = model.dof();
    let q = state_vector("q", args.q, n)?;
    let dq = state_vector("dq", args.dq, n)?;
    let ddq = state_vector("ddq", args.ddq, n)?;
    let frame_name = match args.frame {
        Some(f) => f,
        None => default_frame(&model)?,
    };
    let frame = model.frame_id(&frame_name)?;

    let mut data = model.data();
    model.forward_kinematics(&mut data, &q);
    let frames = frames_json(&model, &data);
    let mut jac = Matrix6xX::zeros(n);
    model.frame_jacobian(&data, frame, Axes::World, &mut jac);
    let jacobian = DMatrix::from_column_slice(6, n, jac.as_slice());
    let mass_matrix = model.mass_matrix(&mut data, &q).clone();
    let gravity = model.gravity_torques(&mut data, &q).as_slice().to_vec();
    let rnea = model.rnea(&mut data, &q, &dq, &ddq, None).as_slice().to_vec();

    println!(
        "robot `{}`: {n} joints, moving mass {:.4} kg, {} frames",
        model.name,
        model.moving_mass(),
        model.frames.len()
    );
    print_joints(&model, &q);
    print_frames(&model, &data);
    print_matrix(&format!("Jacobian of {frame_name} (rows: vx vy vz wx wy wz, world axes)"), &jacobian);
    print_matrix("mass matrix M [kg m²]", &mass_matrix);
    println!("gravity g [Nm]     {}", gravity.iter().map(|x| format!("{x:>10.4}")).collect::<Vec<_>>().join(" "));
    println!("RNEA τ [Nm]        {}", rnea.iter().map(|x| format!("{x:>10.4}")).collect::<Vec<_>>().join(" "));

    if let Some(path) = args.json {
        let out = ModelJson {
            robot: model.name.clone(),
            joints: model
                .joints
                .iter()
                .map(|j| JointJson {
                    name: j.name.clone(),
                    lower: j.limits.lower,
                    upper: j.limits.upper,
                    velocity: j.limits.velocity,
                    effort: j.limits.effort,
                })
                .collect(),
            bodies: model
                .joints
                .iter()
                .map(|j| BodyJson { joint: j.name.clone(), mass: j.body().mass, com: j.body().com().into() })
                .collect(),
            q,
            dq,
            ddq,
            frames,
            jacobian_frame: frame_name,
            jacobian: rows(&jacobian),
            mass_matrix: rows(&mass_matrix),
            gravity,
            rnea,
        };
        std::fs::write(&path, serde_json::to_string_pretty(&out)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The tool frame where the model has one, else the last frame the last joint carries.
fn default_frame(model: &Model) -> anyhow::Result<String> {
    if model.frame_id(lwr4::TOOL_FRAME).is_ok() {
        return Ok(lwr4::TOOL_FRAME.to_string());
    }
    let last = model.dof() - 1;
    let frame = model.frames.iter().rev().find(|f| f.joint == Some(last));
    frame.map(|f| f.name.clone()).context("no frame on the last joint")
}

/// Each frame's pose in the world at the data's q.
fn frames_json(model: &Model, data: &softcontact_dynamics::Data) -> BTreeMap<String, FrameJson> {
    model
        .frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let pose = model.frame_pose(data, softcontact_dynamics::FrameId(i));
            let r = pose.rotation.to_rotation_matrix().into_inner();
            let t = pose.translation.vector;
            (
                f.name.clone(),
                FrameJson {
                    translation: [t.x, t.y, t.z],
                    rotation: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)])),
                },
            )
        })
        .collect()
}

/// The joints' limits, the state and each body's mass and centre of mass.
fn print_joints(model: &Model, q: &[f64]) {
    println!(
        "{:<16} {:>9} {:>9} {:>10} {:>9} {:>9} {:>8}  body COM [m] in joint frame",
        "joint", "lower°", "upper°", "vel [r/s]", "eff [Nm]", "q [rad]", "mass kg"
    );
    for (i, j) in model.joints.iter().enumerate() {
        let c = j.body().com();
        println!(
            "{:<16} {:>9.2} {:>9.2} {:>10.4} {:>9.1} {:>9.4} {:>8.4}  ({:.4}, {:.4}, {:.4})",
            j.name,
            j.limits.lower.to_degrees(),
            j.limits.upper.to_degrees(),
            j.limits.velocity,
            j.limits.effort,
            q[i],
            j.body().mass,
            c.x,
            c.y,
            c.z
        );
        if q[i] < j.limits.lower || q[i] > j.limits.upper {
            println!("  warning: q of {} is outside its limits", j.name);
        }
    }
}

/// Each frame's pose in the world at the data's q, with the joint that carries it.
fn print_frames(model: &Model, data: &softcontact_dynamics::Data) {
    println!("frames in world at q (translation [m], roll-pitch-yaw [deg]), with the joint that carries each:");
    for (i, f) in model.frames.iter().enumerate() {
        let pose = model.frame_pose(data, softcontact_dynamics::FrameId(i));
        let (r, p, y) = pose.rotation.euler_angles();
        let t = pose.translation.vector;
        let carrier = f.joint.map(|j| model.joints[j].name.as_str()).unwrap_or("world");
        println!(
            "  {:<16} ({:>8.4}, {:>8.4}, {:>8.4})  ({:>8.2}, {:>8.2}, {:>8.2})  on {carrier}",
            f.name,
            t.x,
            t.y,
            t.z,
            r.to_degrees(),
            p.to_degrees(),
            y.to_degrees()
        );
    }
}
