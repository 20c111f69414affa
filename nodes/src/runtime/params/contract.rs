//! The checks every node's parameters pass, called from each node's tests (the simulator's too): every
//! parameter declared once with a description, and every number refusing NaN, ±∞, huge and negative values
//! unless the node says why it takes them.

use serde_yaml_ng::{Mapping, Value};

use super::{NodeParams, from_mapping, set_path};
use ros2_client::ParameterValue;

/// Each value the node reads is covered by exactly one declaration, and each declaration has a description
/// and covers a value.
pub fn assert_declared_once<P: NodeParams>(node: &str) {
    let (_, declared) = from_mapping::<P>(node, Mapping::new()).unwrap();
    for (name, _) in &declared.values {
        let n = declared.specs.iter().filter(|s| s.covers(name)).count();
        assert_eq!(n, 1, "{node}: {name} is declared {n} times");
    }
    for s in &declared.specs {
        assert!(declared.values.iter().any(|(n, _)| s.covers(n)), "{node}: {} is no parameter", s.name);
        assert!(!s.description.is_empty(), "{node}: {} has no description", s.name);
    }
}

/// Every number of every node refuses NaN and ±∞, and huge or negative values unless named here
/// (with why): a value reaching the arm is checked whatever the parameter.
pub fn assert_non_finite_refused<P: NodeParams + std::fmt::Debug>(node: &str, huge_ok: &[&str], negative_ok: &[&str]) {
    let (_, declared) = from_mapping::<P>(node, Mapping::new()).unwrap();
    let mut checked = 0;
    for (name, value) in &declared.values {
        let with = |x: f64| -> Value {
            match value {
                ParameterValue::DoubleArray(v) => Value::Sequence(v.iter().map(|_| Value::from(x)).collect()),
                _ => Value::from(x),
            }
        };
        if !matches!(value, ParameterValue::Double(_) | ParameterValue::DoubleArray(_)) {
            continue;
        }
        checked += 1;
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300, -1.0] {
            let allowed = (bad == 1e300 && huge_ok.contains(&name.as_str()))
                || (bad < 0.0 && bad.is_finite() && negative_ok.contains(&name.as_str()));
            let mut m = Mapping::new();
            set_path(&mut m, name, with(bad));
            let taken = from_mapping::<P>(node, m);
            assert!(allowed || taken.is_err(), "{node}: {name} = {bad} is taken: {:?}", taken.map(|t| t.0));
        }
    }
    assert!(checked >= 3, "{node}: only {checked} numbers");
}
