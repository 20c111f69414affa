//! The parameter reference of the whole cell: the shipped files of `config/` and `docs/parameters.md` are
//! what the declarations of the product's nodes and the simulator give, and the simulator's shipped file
//! is valid and spells out its defaults (the product's own are checked in nodes/tests/config.rs).

use std::path::PathBuf;

use softcontact_nodes::runtime::params::reference::{self, yaml};
use softcontact_nodes::runtime::params::{ParamArgs, load};
use softcontact_simcell::sim_arm;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn config(file: &str) -> PathBuf {
    root().join("config").join(file)
}

#[test]
fn the_simulators_parameter_file_is_valid_and_spells_out_its_defaults() {
    let args = ParamArgs { files: vec![config("sim_arm.yaml")], ..Default::default() };
    let (shipped, _) = load::<sim_arm::Params>("sim_arm", &args).unwrap();
    assert_eq!(shipped, sim_arm::Params::default());
    let generated = std::env::temp_dir().join(format!("softcontact-sim_arm-reference-{}.yaml", std::process::id()));
    std::fs::write(&generated, yaml::<sim_arm::Params>("sim_arm", "a test")).unwrap();
    let read = load::<sim_arm::Params>("sim_arm", &ParamArgs { files: vec![generated.clone()], ..Default::default() });
    let _ = std::fs::remove_file(&generated);
    assert_eq!(read.unwrap().0, sim_arm::Params::default(), "a generated file reads back as the defaults");
}

/// A parameter, default, range or description changed in code and not regenerated fails here.
#[test]
fn shipped_parameter_files_and_the_reference_page_are_generated_from_the_declarations() {
    let nodes = softcontact_simcell::parameter_reference();
    for node in &nodes {
        let shipped = std::fs::read_to_string(config(&format!("{}.yaml", node.node))).unwrap();
        assert!(
            shipped == node.yaml(),
            "config/{0}.yaml differs from the declarations: regenerate with `softcontact params {0} > config/{0}.yaml`",
            node.node
        );
    }
    let page = std::fs::read_to_string(root().join("docs/parameters.md")).unwrap();
    assert!(
        page == reference::markdown_all(&nodes),
        "docs/parameters.md differs from the declarations: regenerate with `softcontact params --markdown > docs/parameters.md`"
    );
}
