//! The URDF front end: clear errors for descriptions the dynamics cannot use, and analytic checks on
//! small chains that exercise what the LWR does not (general axes, rotated joint frames, branches of
//! fixed frames).

use softcontact_dynamics::{Error, Model};

fn link(name: &str, mass: f64, com: &str) -> String {
    format!(
        r#"<link name="{name}"><inertial><origin xyz="{com}" rpy="0 0 0"/><mass value="{mass}"/>
           <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>"#
    )
}

fn joint(name: &str, kind: &str, parent: &str, child: &str, origin: &str, axis: &str) -> String {
    format!(
        r#"<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>
           <origin {origin}/><axis xyz="{axis}"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>"#
    )
}

fn robot(parts: &[String]) -> String {
    format!(r#"<?xml version="1.0"?><robot name="test">{}</robot>"#, parts.join("\n"))
}

const L1: f64 = 0.7;
const L2: f64 = 0.45;
const M1: f64 = 1.3;
const M2: f64 = 0.8;

/// A double pendulum of point masses about parallel horizontal axes u = (0.6, 0.8, 0): joint 1 with a
/// general axis under a yawed base, joint 2 in a frame rolled by 90° (so its axis reads differently),
/// and a fixed massless marker frame branching off link 1.
fn double_pendulum() -> String {
    robot(&[
        link("world", 0.0, "0 0 0"),
        joint("base", "fixed", "world", "base", r#"xyz="0 0 1" rpy="0 0 1.1""#, "1 0 0"),
        link("base", 0.0, "0 0 0"),
        joint("j1", "revolute", "base", "l1", r#"xyz="0 0 0" rpy="0 0 0""#, "0.6 0.8 0"),
        link("l1", M1, &format!("0 0 {}", -L1)),
        joint("marker", "fixed", "l1", "mark", r#"xyz="0.1 0 0" rpy="0 0 0""#, "1 0 0"),
        link("mark", 0.0, "0 0 0"),
        joint(
            "j2",
            "continuous",
            "l1",
            "l2",
            &format!(r#"xyz="0 0 {}" rpy="1.5707963267948966 0 0""#, -L1),
            "0.6 0 -0.8",
        ),
        link("l2", M2, &format!("0 {} 0", -L2)),
    ])
}

#[test]
fn double_pendulum_matches_the_textbook() {
    let model = Model::from_urdf_str(&double_pendulum()).unwrap();
    assert_eq!(model.dof(), 2);
    assert_eq!(model.joints[1].limits.lower, f64::NEG_INFINITY, "continuous joints have no position limits");
    let mut data = model.data();
    let g = 9.81;
    for (q1, q2) in [(0.0, 0.0), (0.4, -1.1), (2.0, 0.7), (-2.9, 3.0)] {
        let q = [q1, q2];
        let m = model.mass_matrix(&mut data, &q).clone();
        let c2 = f64::cos(q2);
        let m11 = (M1 + M2) * L1 * L1 + M2 * L2 * L2 + 2.0 * M2 * L1 * L2 * c2;
        let m12 = M2 * L2 * L2 + M2 * L1 * L2 * c2;
        let m22 = M2 * L2 * L2;
        for (ours, exact) in [(m[(0, 0)], m11), (m[(0, 1)], m12), (m[(1, 0)], m12), (m[(1, 1)], m22)] {
            assert!((ours - exact).abs() < 1e-12, "M at {q:?}: {ours} vs {exact}");
        }
        let tau = model.gravity_torques(&mut data, &q).clone();
        let g1 = (M1 + M2) * g * L1 * q1.sin() + M2 * g * L2 * (q1 + q2).sin();
        let g2 = M2 * g * L2 * (q1 + q2).sin();
        assert!((tau[0] - g1).abs() < 1e-12 && (tau[1] - g2).abs() < 1e-12, "g at {q:?}: {tau} vs ({g1}, {g2})");
        // The marker rides on link 1, 0.1 m along its x axis from the joint-1 origin.
        model.forward_kinematics(&mut data, &q);
        let mark = model.frame_pose(&data, model.frame_id("mark").unwrap());
        let l1 = model.frame_pose(&data, model.frame_id("l1").unwrap());
        assert!(((mark.translation.vector - l1.translation.vector).norm() - 0.1).abs() < 1e-12);
    }
}

#[test]
fn fixed_children_add_their_inertia_to_the_moving_body() {
    // One joint carrying a 2 kg point at 0.5 m through a fixed joint: M = m l² about the axis.
    let urdf = robot(&[
        link("world", 0.0, "0 0 0"),
        joint("j", "revolute", "world", "arm", r#"xyz="0 0 0" rpy="0 0 0""#, "0 0 1"),
        link("arm", 1e-6, "0 0 0"),
        joint("tip", "fixed", "arm", "weight", r#"xyz="0.5 0 0" rpy="0.3 0.2 0.1""#, "1 0 0"),
        link("weight", 2.0, "0 0 0"),
    ]);
    let model = Model::from_urdf_str(&urdf).unwrap();
    let mut data = model.data();
    assert!((model.mass_matrix(&mut data, &[0.3])[(0, 0)] - 0.5).abs() < 1e-12);
    assert!((model.moving_mass() - 2.000001).abs() < 1e-12);
}

/// A URDF, a test of the error it must give, and words its message must contain.
type ErrorCase = (String, fn(&Error) -> bool, &'static str);

#[test]
fn errors_name_what_is_wrong() {
    let cases: Vec<ErrorCase> = vec![
        (
            robot(&[
                link("a", 0.0, "0 0 0"),
                joint("j1", "revolute", "a", "b", r#"xyz="0 0 0""#, "0 0 1"),
                link("b", 1.0, "0 0 0"),
                joint("j2", "revolute", "a", "c", r#"xyz="0 0 0""#, "0 0 1"),
                link("c", 1.0, "0 0 0"),
            ]),
            |e| matches!(e, Error::NotASerialChain { link, branches } if link == "a" && branches.len() == 2),
            "not a serial chain",
        ),
        (
            robot(&[link("a", 0.0, "0 0 0"), joint("j", "prismatic", "a", "b", r#"xyz="0 0 0""#, "0 0 1"), link("b", 1.0, "0 0 0")]),
            |e| matches!(e, Error::UnsupportedJoint { joint, .. } if joint == "j"),
            "prismatic",
        ),
        (
            robot(&[link("a", 0.0, "0 0 0"), joint("j", "revolute", "a", "ghost", r#"xyz="0 0 0""#, "0 0 1")]),
            |e| matches!(e, Error::MissingLink { link, .. } if link == "ghost"),
            "ghost",
        ),
        (
            robot(&[link("a", 0.0, "0 0 0"), joint("j", "revolute", "a", "b", r#"xyz="0 0 0""#, "0 0 1"), link("b", 0.0, "0 0 0")]),
            |e| matches!(e, Error::NoInertial { joint } if joint == "j"),
            "no inertial",
        ),
        (
            robot(&[link("a", 0.0, "0 0 0"), joint("j", "fixed", "a", "b", r#"xyz="0 0 0""#, "0 0 1"), link("b", 1.0, "0 0 0")]),
            |e| matches!(e, Error::NoMovableJoint),
            "no movable joint",
        ),
        (
            robot(&[link("a", 0.0, "0 0 0"), link("b", 1.0, "0 0 0")]),
            |e| matches!(e, Error::ManyRoots(r) if r.len() == 2),
            "several root links",
        ),
        (
            robot(&[link("a", 0.0, "0 0 0"), joint("j", "revolute", "a", "b", r#"xyz="0 0 0""#, "0 0 0"), link("b", 1.0, "0 0 0")]),
            |e| matches!(e, Error::ZeroAxis { joint } if joint == "j"),
            "zero or non-finite axis",
        ),
        (
            robot(&[
                link("a", 0.0, "0 0 0"),
                joint("j", "revolute", "a", "b", r#"xyz="0 0 0""#, "0 0 1"),
                r#"<link name="b"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>"#.to_string(),
            ]),
            |e| matches!(e, Error::NonPhysicalInertia { link } if link == "b"),
            "non-physical",
        ),
        ("<robot name='x'><link name='a'>".to_string(), |e| matches!(e, Error::Parse(_)), "invalid URDF"),
    ];
    for (urdf, is_expected, words) in cases {
        let err = Model::from_urdf_str(&urdf).expect_err(words);
        assert!(is_expected(&err), "expected `{words}`, got {err:?}");
        assert!(err.to_string().contains(words), "message `{err}` should say `{words}`");
    }
}

#[test]
fn unknown_frames_and_unreadable_files_are_reported() {
    let model = softcontact_dynamics::lwr4::model();
    let err = model.frame_id("lwr_toool").unwrap_err();
    assert!(err.to_string().contains("lwr_toool") && err.to_string().contains("lwr_tool"), "{err}");
    let err = Model::from_urdf_file("/nonexistent/robot.urdf").unwrap_err();
    assert!(matches!(err, Error::Read { .. }) && err.to_string().contains("/nonexistent/robot.urdf"), "{err}");
}

#[test]
fn the_tool_load_is_the_hand_of_the_urdf() {
    // lwr_hand: 0.20 kg, centre 0.03 m along the sensing frame's z (the hand's box is 0.06 m tall).
    let load = softcontact_dynamics::lwr4::tool_load();
    assert!((load.mass - 0.20).abs() < 1e-12, "{}", load.mass);
    assert!((load.com() - nalgebra::Vector3::new(0.0, 0.0, 0.03)).norm() < 1e-12, "{}", load.com());
}
