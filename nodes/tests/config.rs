//! Every parameter file in config/ is valid for its node as shipped, and the robot overlay layers on
//! top of it: a typo in a shipped file fails here, not on the robot.

use std::path::PathBuf;

use softcontact_nodes::runtime::params::{NodeParams, ParamArgs, load};

fn config(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config").join(file)
}

fn check<P: NodeParams + Default + PartialEq + std::fmt::Debug>(node: &str) -> P {
    let args = ParamArgs { files: vec![config(&format!("{node}.yaml"))], ..Default::default() };
    let (p, declared) = load::<P>(node, &args).unwrap_or_else(|e| panic!("{node}: {e}"));
    assert!(!declared.values.is_empty() && !declared.specs.is_empty());
    let robot = ParamArgs { files: vec![config(&format!("{node}.yaml")), config("robot.yaml")], ..Default::default() };
    load::<P>(node, &robot).unwrap_or_else(|e| panic!("{node} with the robot overlay: {e}"));
    p
}

#[test]
fn shipped_parameter_files_are_valid_and_match_the_defaults() {
    use softcontact_nodes::*;
    // The files spell out the defaults, so that what a user reads is what runs.
    assert_eq!(check::<lwr_driver::Params>("lwr_driver"), Default::default());
    assert_eq!(check::<ft_sensor::Params>("ft_sensor"), Default::default());
    assert_eq!(check::<contact_estimator::Params>("contact_estimator"), Default::default());
    assert_eq!(check::<deformation_controller::Params>("deformation_controller"), Default::default());
}

#[test]
fn unsafe_controller_settings_are_refused() {
    use softcontact_nodes::deformation_controller::Params;
    for bad in [
        "approach_speed:=0.5",
        "max_force:=-1",
        "normal:=[0,0,0]",
        "torque_rate:=.nan",
        "onset_confirm:=0",
        "force_limit:=200",
        "initial_surface:=[.nan,0,0.3]",
        "initial_surface:=[0,.inf,0.3]",
        "initial_surface:=[1e300,0,0.3]",
        "initial_surface:=[0,0]",
    ] {
        let args = ParamArgs { overrides: vec![bad.into()], ..Default::default() };
        assert!(load::<Params>("deformation_controller", &args).is_err(), "{bad} accepted");
    }
}

#[test]
fn dead_after_outside_its_range_is_refused_by_every_node_that_has_it() {
    use softcontact_nodes::*;
    for bad in ["dead_after:=0.05", "dead_after:=61", "dead_after:=.inf", "dead_after:=-1"] {
        let args = ParamArgs { overrides: vec![bad.into()], ..Default::default() };
        assert!(load::<lwr_driver::Params>("lwr_driver", &args).is_err(), "lwr_driver: {bad} accepted");
        assert!(load::<contact_estimator::Params>("contact_estimator", &args).is_err(), "estimator: {bad}");
        assert!(load::<deformation_controller::Params>("deformation_controller", &args).is_err(), "controller: {bad}");
    }
    let args = ParamArgs { overrides: vec!["dead_after:=0.1".into()], ..Default::default() };
    assert!(load::<contact_estimator::Params>("contact_estimator", &args).is_ok());
    // The controller's must exceed restart_after (0.1 s by default): a gap is a restart before it is death.
    assert!(load::<deformation_controller::Params>("deformation_controller", &args).is_err());
}
