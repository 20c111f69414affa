//! Node parameters the ROS 2 way: ROS 2 parameter YAML files (`node: ros__parameters: {…}`, `/**`
//! for every node) merged in order, then `-p name:=value` overrides, read into one typed struct per node
//! that rejects unknown names and checks its values before the node starts. The same values are
//! declared on the node, so `ros2 param list/get/describe` show what the node runs with.

pub mod contract;
pub mod reference;

use std::path::{Path, PathBuf};

use ros2_client::ParameterValue;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_yaml_ng::{Mapping, Value};

/// The parameter arguments every node binary takes (a ROS 2 `--ros-args` subset).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ParamArgs {
    /// ROS 2 parameter YAML file; repeat to layer files (later ones win).
    #[arg(long = "params-file", value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// One parameter, `name:=value` (value in YAML syntax); wins over the files.
    #[arg(short = 'p', long = "param", value_name = "NAME:=VALUE")]
    pub overrides: Vec<String>,
    /// A ROS 2 name remapping: `FROM:=TO` for a topic or service, `__node:=NAME`, `__ns:=/NS`; prefixed
    /// `NODE:` for one node of lwr_control (docs/architecture.md, "Names").
    #[arg(short = 'r', long = "remap", value_name = "FROM:=TO")]
    pub remaps: Vec<String>,
    /// The process's enclave on a secure graph (`ROS_SECURITY_ENABLE=true`; docs/safety.md): its folder in
    /// `ROS_SECURITY_KEYSTORE`. `ROS_SECURITY_ENCLAVE_OVERRIDE` wins over it; without either, `/`.
    #[arg(short = 'e', long = "enclave", value_name = "NAME")]
    pub enclave: Option<String>,
    /// Accepted for `ros2 run` compatibility; the options above follow it.
    #[arg(long = "ros-args", hide = true)]
    pub ros_args: bool,
}

impl ParamArgs {
    /// The arguments of one node of a composed process: every file (each node reads its own section),
    /// the overrides without a node (`name:=value`) and those for this one (`node:name:=value`).
    pub fn for_node(&self, node: &str) -> ParamArgs {
        let overrides = self
            .overrides
            .iter()
            .filter_map(|o| {
                // Without `:=` it is kept, for `load` to refuse.
                let Some((name, _)) = o.split_once(":=") else { return Some(o.clone()) };
                match name.split_once(':') {
                    None => Some(o.clone()),
                    Some((n, _)) if n == node => Some(o[n.len() + 1..].to_string()),
                    Some(_) => None,
                }
            })
            .collect();
        ParamArgs {
            files: self.files.clone(),
            overrides,
            remaps: self.remaps.clone(),
            enclave: self.enclave.clone(),
            ros_args: self.ros_args,
        }
    }

    /// Refuses a `NODE:` prefix, in `-p NODE:name:=value` or `-r NODE:FROM:=TO`, that names none of the
    /// `nodes` a composed process hosts: a misspelt node would silently get nothing.
    pub fn check_node_prefixes(&self, nodes: &[&str]) -> Result<(), ParamError> {
        let prefix =
            |arg: &str| arg.split_once(":=").and_then(|(left, _)| left.split_once(':')).map(|(n, _)| n.to_owned());
        if let Some(arg) = self.remaps.iter().find(|r| r.starts_with("__node:=") || r.starts_with("__name:=")) {
            let known = nodes.join(", ");
            return Err(ParamError::Remap(format!(
                "-r `{arg}` would give all of {known} one name: prefix it with the node, e.g. `{}:{arg}`",
                nodes[0]
            )));
        }
        for (arg, what) in self.overrides.iter().map(|o| (o, "-p")).chain(self.remaps.iter().map(|r| (r, "-r"))) {
            if let Some(node) = prefix(arg).filter(|n| !nodes.contains(&n.as_str())) {
                let known = nodes.join(", ");
                return Err(ParamError::Remap(format!(
                    "{what} `{arg}`: no node `{node}` here (this process hosts {known})"
                )));
            }
        }
        Ok(())
    }
}

/// A node's parameter struct: its defaults come from serde; each parameter is declared once, in
/// [`declare`](Self::declare), with its description and the values it takes — the one place that both
/// checks it at start-up and describes it over ROS (`ros2 param describe`).
pub trait NodeParams: Serialize + DeserializeOwned {
    /// Declares every parameter (a nested one by its top-level name) with what it means and its range.
    fn declare(&self, d: &mut Declarations);

    /// The first value outside its declared range, with why.
    fn validate(&self) -> Result<(), String> {
        let mut d = Declarations::default();
        self.declare(&mut d);
        d.error.map_or(Ok(()), Err)
    }

    /// What each parameter means and takes, as declared.
    fn specs(&self) -> Vec<Spec> {
        let mut d = Declarations::default();
        self.declare(&mut d);
        d.specs
    }
}

/// One parameter as its node declares it.
#[derive(Debug, Clone, PartialEq)]
pub struct Spec {
    pub name: String,
    pub description: String,
    pub range: Range,
}

/// The values a parameter takes.
#[derive(Debug, Clone, PartialEq)]
pub enum Range {
    /// A finite number in [lo, hi], or in (lo, hi] when `above` (lo itself excluded).
    Number {
        lo: f64,
        hi: f64,
        above: bool,
    },
    /// Every entry of an array in [lo, hi].
    Each {
        lo: f64,
        hi: f64,
    },
    Integer {
        lo: i64,
        hi: i64,
    },
    /// A rule the node checks, in words.
    Rule(String),
}

/// A number as errors show it: in exponent form when very large or small (1e300, not 301 digits).
pub struct Shown(pub f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let size = self.0.abs();
        if size.is_finite() && (size >= 1e9 || (size > 0.0 && size < 1e-6)) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

impl std::fmt::Display for Range {
    /// As the errors, the parameter files and docs/parameters.md say it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Range::Number { lo, hi, above: false } if *hi == f64::MAX => write!(f, "≥ {lo}"),
            Range::Number { lo, hi, above: true } if *hi == f64::MAX => write!(f, "> {lo}"),
            Range::Number { lo, hi, above: false } => write!(f, "{lo} to {hi}"),
            Range::Number { lo, hi, above: true } => write!(f, "> {lo}, ≤ {hi}"),
            Range::Each { lo, hi } => write!(f, "{lo} to {hi}, each entry"),
            Range::Integer { lo, hi } => write!(f, "a whole number {lo} to {hi}"),
            Range::Rule(rule) => write!(f, "{rule}"),
        }
    }
}

impl Spec {
    /// The ROS parameter descriptor: description, read-only (nodes read their parameters at start-up),
    /// the numeric range where there is one, and in words what a ROS range cannot say.
    pub fn descriptor(&self) -> ros2_client::parameters::ParameterDescriptor {
        use ros2_client::parameters::{NumericRange, ParameterDescriptor, ParameterType};
        let (range, constraints) = match &self.range {
            Range::Number { lo, hi, above } => (
                NumericRange::FloatingPointRange { from_value: *lo, to_value: *hi, step: 0.0 },
                if *above { format!("greater than {lo}") } else { String::new() },
            ),
            Range::Each { lo, hi } => (NumericRange::NotSpecified, format!("every entry in [{lo}, {hi}]")),
            Range::Integer { lo, hi } => {
                (NumericRange::IntegerRange { from_value: *lo, to_value: *hi, step: 0 }, String::new())
            }
            Range::Rule(rule) => (NumericRange::NotSpecified, rule.clone()),
        };
        ParameterDescriptor {
            name: self.name.clone(),
            param_type: ParameterType::NotSet,
            description: self.description.clone(),
            additional_constraints: constraints,
            read_only: true,
            dynamic_typing: false,
            range,
        }
    }

    /// Whether the flattened parameter `name` (`a.b` is part of `a`) is this one.
    pub fn covers(&self, name: &str) -> bool {
        name == self.name || name.strip_prefix(self.name.as_str()).is_some_and(|rest| rest.starts_with('.'))
    }
}

/// The declarations of one node's parameters, and the first value found outside its range.
#[derive(Debug, Default)]
pub struct Declarations {
    specs: Vec<Spec>,
    error: Option<String>,
}

impl Declarations {
    fn declare(&mut self, name: &str, description: &str, range: Range, fault: Option<String>) {
        self.specs.push(Spec { name: name.into(), description: description.into(), range });
        if self.error.is_none() {
            self.error = fault;
        }
    }

    /// The first value found outside its range.
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// A finite number in (lo, hi].
    pub fn above(&mut self, name: &str, value: f64, (lo, hi): (f64, f64), description: &str) {
        let ok = value.is_finite() && value > lo && value <= hi;
        let range = Range::Number { lo, hi, above: true };
        let fault = (!ok).then(|| format!("{name} must be {range}, not {}", Shown(value)));
        self.declare(name, description, range, fault);
    }

    /// A finite number in [lo, hi].
    pub fn within(&mut self, name: &str, value: f64, (lo, hi): (f64, f64), description: &str) {
        let ok = value.is_finite() && (lo..=hi).contains(&value);
        let range = Range::Number { lo, hi, above: false };
        let fault = (!ok).then(|| format!("{name} must be {range}, not {}", Shown(value)));
        self.declare(name, description, range, fault);
    }

    /// Every entry in [lo, hi].
    pub fn each(&mut self, name: &str, values: &[f64], (lo, hi): (f64, f64), description: &str) {
        let ok = values.iter().all(|x| x.is_finite() && (lo..=hi).contains(x));
        let range = Range::Each { lo, hi };
        let shown: Vec<String> = values.iter().map(|v| Shown(*v).to_string()).collect();
        let fault = (!ok).then(|| format!("{name} must be {range}, not [{}]", shown.join(", ")));
        self.declare(name, description, range, fault);
    }

    /// A whole number in [lo, hi].
    pub fn integer(&mut self, name: &str, value: i64, (lo, hi): (i64, i64), description: &str) {
        let range = Range::Integer { lo, hi };
        let fault = (!(lo..=hi).contains(&value)).then(|| format!("{name} must be {range}, not {value}"));
        self.declare(name, description, range, fault);
    }

    /// A value the node checks itself: `check` says whether it holds (and why not), `rule` what it is.
    pub fn rule(&mut self, name: &str, check: Result<(), String>, rule: &str, description: &str) {
        let fault = check.err().map(|why| format!("{name}: {why}"));
        self.declare(name, description, Range::Rule(rule.into()), fault);
    }

    /// A check of several parameters together (the first fault is kept).
    pub fn together(&mut self, check: Result<(), String>) {
        if self.error.is_none() {
            self.error = check.err();
        }
    }

    /// A direction in the world: three finite numbers, not all zero.
    pub fn direction(&mut self, name: &str, v: [f64; 3], description: &str) {
        let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let check = if norm.is_normal() { Ok(()) } else { Err(format!("a zero direction {v:?}")) };
        self.rule(name, check, "a non-zero direction", description);
    }

    /// The peers' service mapping (`service_mapping`), for the services the node serves and calls.
    pub fn service_mapping(&mut self, mapping: &str, description: &str) {
        let check = crate::runtime::ros::service_mapping(mapping).map(|_| ()).map_err(|e| e.to_string());
        self.rule("service_mapping", check, "cyclone, enhanced or basic", description);
    }

    /// The contact onset's detector (`onset_threshold`, `onset_confirm`), the same in every node that
    /// finds the surface.
    pub fn onset(&mut self, threshold: f64, confirm: usize) {
        self.above("onset_threshold", threshold, (0.0, 50.0), "normal force that marks the contact onset [N]");
        let what = "consecutive readings above onset_threshold that confirm the onset";
        self.integer("onset_confirm", confirm as i64, (1, 100), what);
    }

    /// The ROS 2 switch every node has.
    pub fn use_sim_time(&mut self) {
        self.any("use_sim_time", "stamp messages with the simulated time of /clock");
    }

    /// A parameter any value of its type suits (a switch, a name).
    pub fn any(&mut self, name: &str, description: &str) {
        self.declare(name, description, Range::Rule(String::new()), None);
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: not a ROS 2 parameter file: {reason}")]
    Format { path: PathBuf, reason: String },
    #[error("parameter override `{0}`: expected name:=value")]
    Override(String),
    #[error("parameter override `{name}`: its value is not YAML: {reason}")]
    OverrideValue { name: String, reason: String },
    #[error("parameters of {node}: {reason}")]
    Invalid { node: String, reason: String },
    #[error("{0}")]
    Remap(String),
}

/// What a node declares on ROS: its parameters' values, flattened (`a.b` for nested ones), their specs,
/// and the names the command line gave it.
#[derive(Debug, Clone, Default)]
pub struct Declared {
    pub values: Vec<(String, ParameterValue)>,
    pub specs: Vec<Spec>,
    pub remapping: crate::runtime::names::Remapping,
    /// `--enclave`: the process's enclave on a secure graph.
    pub enclave: Option<String>,
}

/// The largest parameter or model file read \[bytes\]: memory stays bounded whatever the path names.
pub const MAX_FILE: u64 = 1 << 20;

/// A YAML file's text: a regular file of at most [`MAX_FILE`] bytes nested at most [`MAX_NESTING`]
/// levels ([`check_nesting`]); a device, a FIFO, a larger or a deeper file is an error.
pub fn read_small(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    // Before opening: opening a FIFO blocks until a writer comes.
    if !std::fs::metadata(path)?.is_file() {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a regular file"));
    }
    let file = std::fs::File::open(path)?;
    let mut text = String::new();
    file.take(MAX_FILE + 1).read_to_string(&mut text)?;
    if text.len() as u64 > MAX_FILE {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("larger than {MAX_FILE} bytes")));
    }
    check_nesting(&text).map_err(|why| std::io::Error::new(std::io::ErrorKind::InvalidData, why))?;
    Ok(text)
}

/// The deepest nesting a parameter file or override may have: flow brackets (`[`, `{`) and block
/// indentation, in levels. The deepest parameter is three levels down; a YAML parser takes time and
/// stack in the depth, so a hostile file is refused before it is parsed.
pub const MAX_NESTING: usize = 32;
/// The widest block indentation of a parameter file's line \[characters\].
pub const MAX_INDENT: usize = 4 * MAX_NESTING;

/// The text's nesting, if within [`MAX_NESTING`] levels of brackets and [`MAX_INDENT`] characters of
/// indentation (quoted strings and comments are skipped); the error names the line.
pub fn check_nesting(text: &str) -> Result<(), String> {
    let mut depth = 0usize;
    let mut quote: Option<char> = None;
    for (number, line) in text.lines().enumerate() {
        let indent = line.len() - line.trim_start_matches([' ', '\t']).len();
        if indent > MAX_INDENT {
            return Err(format!("line {}: indented {indent} characters, at most {MAX_INDENT}", number + 1));
        }
        let mut previous = ' ';
        for c in line.chars() {
            let starts_scalar = matches!(previous, ' ' | '\t' | '[' | '{' | ',' | ':');
            previous = c;
            match (quote, c) {
                (Some(q), c) if c == q => quote = None,
                (Some(_), _) => {}
                (None, '"' | '\'') if starts_scalar => quote = Some(c),
                (None, '#') => break,
                (None, '[' | '{') => {
                    depth += 1;
                    if depth > MAX_NESTING {
                        return Err(format!("line {}: nested deeper than {MAX_NESTING} levels", number + 1));
                    }
                }
                (None, ']' | '}') => depth = depth.saturating_sub(1),
                _ => {}
            }
        }
    }
    Ok(())
}

/// Reads the parameters of `node` from `args`, checks them, and returns them with what to declare.
pub fn load<P: NodeParams>(node: &str, args: &ParamArgs) -> Result<(P, Declared), ParamError> {
    let remapping = crate::runtime::names::Remapping::parse(node, &args.remaps).map_err(ParamError::Remap)?;
    // A file's section for this node: `/**`, then its own name, then the name and the fully qualified
    // name `-r __node` and `-r __ns` gave it (later ones win), as ROS 2 reads them.
    let name = remapping.node_name(node);
    let qualified = format!("{}/{name}", remapping.namespace().trim_end_matches('/'));
    let mut keys = vec!["/**".to_string(), node.to_string(), format!("/{node}")];
    for key in [name.to_string(), qualified] {
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let mut merged = Mapping::new();
    for path in &args.files {
        let text = read_small(path).map_err(|source| ParamError::Io { path: path.clone(), source })?;
        merge(&mut merged, node_section(&keys, path, &text)?);
    }
    for o in &args.overrides {
        let (name, value) = o.split_once(":=").ok_or_else(|| ParamError::Override(o.clone()))?;
        let bad_value =
            |reason: String| ParamError::OverrideValue { name: name.trim().chars().take(80).collect(), reason };
        check_nesting(value).map_err(bad_value)?;
        let value: Value = serde_yaml_ng::from_str(value).map_err(|e| bad_value(e.to_string()))?;
        set_path(&mut merged, name.trim(), value);
    }
    let (params, declared) = from_mapping(node, merged)?;
    Ok((params, Declared { remapping, enclave: args.enclave.clone(), ..declared }))
}

/// The typed parameters from a merged mapping, checked, with their flat list.
pub fn from_mapping<P: NodeParams>(node: &str, mapping: Mapping) -> Result<(P, Declared), ParamError> {
    let invalid = |reason: String| ParamError::Invalid { node: node.into(), reason };
    // Through text, so that a type error names the parameter it is about.
    let text = serde_yaml_ng::to_string(&mapping).map_err(|e| invalid(e.to_string()))?;
    let params: P = serde_yaml_ng::from_str(&text).map_err(|e| invalid(e.to_string()))?;
    params.validate().map_err(invalid)?;
    let value = serde_yaml_ng::to_value(&params).map_err(|e| invalid(e.to_string()))?;
    let mut values = Vec::new();
    flatten("", &value, &mut values);
    let specs = params.specs();
    Ok((params, Declared { values, specs, ..Default::default() }))
}

/// The `ros__parameters` of `node` in one file: the `/**` section, then the node's own (`node` or
/// `/node`).
fn node_section(keys: &[String], path: &Path, text: &str) -> Result<Mapping, ParamError> {
    let format = |reason: String| ParamError::Format { path: path.to_owned(), reason };
    let doc: Value = serde_yaml_ng::from_str(text).map_err(|e| format(e.to_string()))?;
    let top = match doc {
        Value::Mapping(m) => m,
        Value::Null => return Ok(Mapping::new()),
        _ => return Err(format("the top level must map node names to `ros__parameters`".into())),
    };
    if let Some((key, _)) = top.iter().find(|(_, v)| v.get("ros__parameters").is_none()) {
        return Err(format(format!("`{}` has no `ros__parameters` mapping", key.as_str().unwrap_or("?"))));
    }
    let mut out = Mapping::new();
    for key in keys {
        let Some(section) = top.get(key.as_str()) else { continue };
        match section.get("ros__parameters") {
            Some(Value::Mapping(m)) => merge(&mut out, m.clone()),
            Some(Value::Null) => {}
            _ => return Err(format(format!("`{key}` has no `ros__parameters` mapping"))),
        }
    }
    Ok(out)
}

/// Later values win; nested mappings merge key by key.
fn merge(into: &mut Mapping, from: Mapping) {
    for (k, v) in from {
        match (into.get_mut(&k), v) {
            (Some(Value::Mapping(a)), Value::Mapping(b)) => merge(a, b),
            (_, v) => {
                into.insert(k, v);
            }
        }
    }
}

/// Sets `a.b.c` in nested mappings (ROS 2 names nested parameters with dots).
fn set_path(into: &mut Mapping, name: &str, value: Value) {
    match name.split_once('.') {
        None => {
            into.insert(Value::from(name), value);
        }
        Some((head, rest)) => {
            let entry = into.entry(Value::from(head)).or_insert_with(|| Value::Mapping(Mapping::new()));
            if !entry.is_mapping() {
                *entry = Value::Mapping(Mapping::new());
            }
            set_path(entry.as_mapping_mut().expect("made a mapping above"), rest, value);
        }
    }
}

fn flatten(prefix: &str, value: &Value, out: &mut Vec<(String, ParameterValue)>) {
    let name = |k: &str| if prefix.is_empty() { k.to_string() } else { format!("{prefix}.{k}") };
    match value {
        // A structured parameter with nothing set (`arm_effects: {}`) is still a parameter.
        Value::Mapping(m) if m.is_empty() && !prefix.is_empty() => {
            out.push((prefix.to_string(), ParameterValue::NotSet))
        }
        Value::Mapping(m) => {
            for (k, v) in m {
                let key = k.as_str().map(str::to_string).unwrap_or_else(|| format!("{k:?}"));
                flatten(&name(&key), v, out);
            }
        }
        Value::Tagged(t) => flatten(prefix, &t.value, out),
        v => out.push((prefix.to_string(), parameter_value(v))),
    }
}

/// A YAML value as a ROS 2 parameter value (arrays must be of one type, as in ROS 2).
fn parameter_value(v: &Value) -> ParameterValue {
    match v {
        Value::Null => ParameterValue::NotSet,
        Value::Bool(b) => ParameterValue::Boolean(*b),
        Value::Number(n) if n.is_i64() => ParameterValue::Integer(n.as_i64().expect("checked")),
        Value::Number(n) => ParameterValue::Double(n.as_f64().unwrap_or(f64::NAN)),
        Value::String(s) => ParameterValue::String(s.clone()),
        Value::Sequence(items) => {
            if items.iter().all(Value::is_bool) {
                ParameterValue::BooleanArray(items.iter().filter_map(Value::as_bool).collect())
            } else if items.iter().all(Value::is_i64) {
                ParameterValue::IntegerArray(items.iter().filter_map(Value::as_i64).collect())
            } else if items.iter().all(Value::is_number) {
                ParameterValue::DoubleArray(items.iter().filter_map(Value::as_f64).collect())
            } else {
                ParameterValue::StringArray(
                    items.iter().map(|i| serde_yaml_ng::to_string(i).unwrap_or_default().trim().to_string()).collect(),
                )
            }
        }
        other => ParameterValue::String(serde_yaml_ng::to_string(other).unwrap_or_default().trim().to_string()),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_node_prefix_naming_no_hosted_node_is_refused() {
        let args = |o: &[&str], r: &[&str]| super::ParamArgs {
            overrides: o.iter().map(|s| s.to_string()).collect(),
            remaps: r.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        };
        let hosted = ["lwr_driver", "ft_sensor"];
        assert!(
            args(&["ft_sensor:tare_after:=1", "dead_after:=1"], &["lwr_driver:__ns:=/a", "a:=b"])
                .check_node_prefixes(&hosted)
                .is_ok()
        );
        let e = args(&["ft_sensr:tare_after:=1"], &[]).check_node_prefixes(&hosted).unwrap_err().to_string();
        assert!(e.contains("ft_sensr") && e.contains("lwr_driver, ft_sensor"), "{e}");
        assert!(args(&[], &["driver:__ns:=/a"]).check_node_prefixes(&hosted).is_err());
        let e = args(&[], &["__node:=ctl"]).check_node_prefixes(&hosted).unwrap_err().to_string();
        assert!(e.contains("lwr_driver:__node:=ctl"), "{e}");
    }

    use super::*;
    use serde::Deserialize;

    #[test]
    fn a_deeply_nested_parameter_file_is_refused_before_it_is_parsed() {
        let dir = std::env::temp_dir().join(format!("softcontact-nesting-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let deep = 100_000;
        let hostile = [
            format!("lwr_driver:\n  ros__parameters:\n    x: {}{}\n", "[".repeat(deep), "]".repeat(deep)),
            format!("lwr_driver:\n  ros__parameters:\n    x: {}1{}\n", "{a: ".repeat(deep), "}".repeat(deep)),
            (0..1000).map(|i| format!("{}a{i}:\n", " ".repeat(i))).collect(),
        ];
        for (i, text) in hostile.iter().enumerate() {
            let path = dir.join(format!("deep{i}.yaml"));
            std::fs::write(&path, text.as_bytes()).unwrap();
            let args = ParamArgs { files: vec![path], ..Default::default() };
            let start = std::time::Instant::now();
            let refused = load::<crate::lwr_driver::Params>("lwr_driver", &args).map(|_| ()).unwrap_err();
            assert!(start.elapsed().as_secs_f64() < 0.5, "case {i}: {:?} to refuse", start.elapsed());
            assert!(refused.to_string().contains("line"), "case {i}: {refused}");
        }
        let override_ = format!("x:={}{}", "[".repeat(deep), "]".repeat(deep));
        let args = ParamArgs { overrides: vec![override_], ..Default::default() };
        assert!(matches!(
            load::<crate::lwr_driver::Params>("lwr_driver", &args),
            Err(ParamError::OverrideValue { .. })
        ));
        // Quotes, apostrophes and comments do not count.
        let fine =
            "a: \"[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[\"\nb: it's [1, 2] # {{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{{\n";
        assert_eq!(check_nesting(fine), Ok(()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Demo {
        rate: f64,
        name: String,
        gains: Gains,
        joints: Vec<f64>,
    }
    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Gains {
        kp: f64,
        kd: f64,
    }
    impl Default for Gains {
        fn default() -> Self {
            Self { kp: 1.0, kd: 2.0 }
        }
    }
    impl Default for Demo {
        fn default() -> Self {
            Self { rate: 100.0, name: "a".into(), gains: Gains::default(), joints: vec![1.0, 2.0] }
        }
    }
    impl NodeParams for Demo {
        fn declare(&self, d: &mut Declarations) {
            d.above("rate", self.rate, (0.0, 1e3), "how often");
            d.any("name", "what it is called");
            d.each("gains", &[self.gains.kp, self.gains.kd], (0.0, 10.0), "PD gains");
            d.any("joints", "positions");
        }
    }

    #[test]
    fn a_renamed_or_namespaced_node_reads_the_sections_of_its_new_names_after_its_own() {
        let f = file(
            "/**:\n  ros__parameters: {rate: 1.0}\ndemo:\n  ros__parameters: {rate: 2.0, name: own}\n\
             d2:\n  ros__parameters: {rate: 3.0}\n/cell2/d2:\n  ros__parameters: {name: qualified}\n",
        );
        let with =
            |remaps: &[&str]| ParamArgs { remaps: remaps.iter().map(|r| r.to_string()).collect(), ..args(&[&f], &[]) };
        let (p, _): (Demo, _) = load("demo", &with(&[])).unwrap();
        assert_eq!((p.rate, p.name.as_str()), (2.0, "own"));
        let (p, d): (Demo, _) = load("demo", &with(&["__node:=d2", "__ns:=/cell2"])).unwrap();
        assert_eq!((p.rate, p.name.as_str()), (3.0, "qualified"));
        assert_eq!((d.remapping.node_name("demo"), d.remapping.namespace()), ("d2", "/cell2"));
    }

    fn file(text: &str) -> tempfile_path::TempPath {
        tempfile_path::TempPath::with(text)
    }

    /// A file in the system's temporary folder, removed on drop.
    mod tempfile_path {
        pub struct TempPath(pub std::path::PathBuf);
        impl TempPath {
            pub fn with(text: &str) -> Self {
                use std::sync::atomic::{AtomicUsize, Ordering};
                static N: AtomicUsize = AtomicUsize::new(0);
                let p = std::env::temp_dir().join(format!(
                    "softcontact-params-{}-{}.yaml",
                    std::process::id(),
                    N.fetch_add(1, Ordering::Relaxed)
                ));
                std::fs::write(&p, text).unwrap();
                Self(p)
            }
        }
        impl Drop for TempPath {
            fn drop(&mut self) {
                let _ = std::fs::remove_file(&self.0);
            }
        }
    }

    fn args(files: &[&tempfile_path::TempPath], overrides: &[&str]) -> ParamArgs {
        ParamArgs {
            files: files.iter().map(|f| f.0.clone()).collect(),
            overrides: overrides.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        }
    }

    /// Every parameter of every node is declared exactly once, with a description; no declaration
    /// names a parameter the node does not have.
    #[test]
    fn a_device_or_a_huge_file_is_refused_not_read() {
        let args = |f: &str| ParamArgs { files: vec![f.into()], ..Default::default() };
        for path in ["/dev/zero", "/dev/urandom", "/"] {
            let err = load::<crate::deformation_controller::Params>("deformation_controller", &args(path));
            assert!(err.is_err(), "{path}");
        }
        // A FIFO: refused without waiting for a writer.
        let fifo = std::env::temp_dir().join(format!("softcontact-params-fifo-{}", std::process::id()));
        let _ = std::fs::remove_file(&fifo);
        if std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success()) {
            let err =
                load::<crate::deformation_controller::Params>("deformation_controller", &args(fifo.to_str().unwrap()));
            let _ = std::fs::remove_file(&fifo);
            assert!(err.is_err(), "a FIFO");
        }
        let big = tempfile_path::TempPath::with(&"# padding\n".repeat(200_000));
        assert!(
            load::<crate::deformation_controller::Params>("deformation_controller", &args(big.0.to_str().unwrap()))
                .is_err()
        );
    }

    #[test]
    fn every_parameter_of_every_node_is_declared_once_with_its_description() {
        contract::assert_declared_once::<crate::deformation_controller::Params>("deformation_controller");
        contract::assert_declared_once::<crate::lwr_driver::Params>("lwr_driver");
        contract::assert_declared_once::<crate::ft_sensor::Params>("ft_sensor");
        contract::assert_declared_once::<crate::contact_estimator::Params>("contact_estimator");
        contract::assert_declared_once::<Demo>("demo");
    }

    #[test]
    fn no_node_takes_a_non_finite_huge_or_negative_number() {
        contract::assert_non_finite_refused::<crate::deformation_controller::Params>(
            "deformation_controller",
            &[],
            &["normal"],
        );
        contract::assert_non_finite_refused::<crate::lwr_driver::Params>("lwr_driver", &[], &[]);
        // tare_after: negative is "never".
        contract::assert_non_finite_refused::<crate::ft_sensor::Params>("ft_sensor", &[], &["tare_after"]);
        contract::assert_non_finite_refused::<crate::contact_estimator::Params>(
            "contact_estimator",
            &[],
            &["normal", "offset_range"],
        );
    }

    #[test]
    fn a_declaration_becomes_the_ros_descriptor() {
        let (_, declared) = from_mapping::<crate::deformation_controller::Params>("c", Mapping::new()).unwrap();
        let spec = |name: &str| declared.specs.iter().find(|s| s.name == name).unwrap().descriptor();
        let limit = spec("force_limit");
        assert!(limit.read_only && limit.description.contains("backs off"));
        assert!(matches!(
            limit.range,
            ros2_client::parameters::NumericRange::FloatingPointRange { from_value: 250.0, to_value: 500.0, .. }
        ));
        assert_eq!(limit.additional_constraints, "greater than 250");
        let confirm = spec("onset_confirm");
        assert!(matches!(
            confirm.range,
            ros2_client::parameters::NumericRange::IntegerRange { from_value: 1, to_value: 100, .. }
        ));
        assert_eq!(
            spec("move_duration").additional_constraints,
            "[shortest, longest] within [0.01, 3600] s, shortest < longest"
        );
        // Out of its range, a value is refused with the declared range.
        let mut p = crate::deformation_controller::Params { force_limit: 600.0, ..Default::default() };
        assert_eq!(p.validate().unwrap_err(), "force_limit must be > 250, ≤ 500, not 600");
        p.force_limit = 1e300;
        assert_eq!(p.validate().unwrap_err(), "force_limit must be > 250, ≤ 500, not 1e300");
        p.force_limit = f64::NAN;
        assert!(p.validate().is_err());
    }

    #[test]
    fn files_layer_and_overrides_win() {
        let base = file(
            "/**:\n  ros__parameters:\n    rate: 50.0\ndemo:\n  ros__parameters:\n    gains: {kp: 3.0}\nother:\n  ros__parameters:\n    rate: 7.0\n",
        );
        let robot = file("/demo:\n  ros__parameters:\n    name: robot\n    gains: {kd: 4.0}\n");
        let (p, Declared { values: flat, .. }): (Demo, _) =
            load("demo", &args(&[&base, &robot], &["rate:=25", "gains.kp:=9"])).unwrap();
        assert_eq!(
            p,
            Demo { rate: 25.0, name: "robot".into(), gains: Gains { kp: 9.0, kd: 4.0 }, joints: vec![1.0, 2.0] }
        );
        let names: Vec<&str> = flat.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["rate", "name", "gains.kp", "gains.kd", "joints"]);
        assert!(matches!(flat[4].1, ParameterValue::DoubleArray(ref v) if v == &[1.0, 2.0]));
    }

    #[test]
    fn unknown_names_bad_values_and_bad_files_are_refused() {
        let typo = file("demo:\n  ros__parameters:\n    rte: 5.0\n");
        let e = load::<Demo>("demo", &args(&[&typo], &[])).unwrap_err().to_string();
        assert!(e.contains("rte"), "{e}");
        let e = load::<Demo>("demo", &args(&[], &["rate:=-1"])).unwrap_err().to_string();
        assert!(e.contains("rate must be > 0, ≤ 1000"), "{e}");
        let e = load::<Demo>("demo", &args(&[], &["rate:=fast"])).unwrap_err().to_string();
        assert!(e.contains("rate"), "{e}");
        assert!(matches!(load::<Demo>("demo", &args(&[], &["rate=1"])), Err(ParamError::Override(_))));
        // A value that is not YAML is named as such, with the parser's reason, not as a missing `:=`.
        let e = load::<Demo>("demo", &args(&[], &["gains:={kp: 1, kp: 2}"])).unwrap_err().to_string();
        assert!(e.contains("`gains`") && e.contains("not YAML") && e.contains("duplicate"), "{e}");
        let flat = file("rate: 5.0\n");
        assert!(matches!(load::<Demo>("demo", &args(&[&flat], &[])), Err(ParamError::Format { .. })));
        let broken = file("demo: [unclosed\n");
        assert!(matches!(load::<Demo>("demo", &args(&[&broken], &[])), Err(ParamError::Format { .. })));
        let missing = ParamArgs { files: vec!["/nonexistent/x.yaml".into()], ..Default::default() };
        assert!(matches!(load::<Demo>("demo", &missing), Err(ParamError::Io { .. })));
    }

    #[test]
    fn a_composed_process_gives_each_node_its_own_overrides() {
        let a = args(&[], &["rate:=5", "demo:gains.kp:=9", "other:rate:=7", "broken"]);
        let demo = a.for_node("demo");
        assert_eq!(demo.overrides, ["rate:=5", "gains.kp:=9", "broken"]);
        assert_eq!(a.for_node("other").overrides, ["rate:=5", "rate:=7", "broken"]);
        // A malformed one still reaches `load`, which refuses it.
        assert!(matches!(load::<Demo>("demo", &demo), Err(ParamError::Override(_))));
        let (p, _): (Demo, _) =
            load("demo", &args(&[], &["rate:=5", "demo:gains.kp:=9", "x:y:=1"]).for_node("demo")).unwrap();
        assert_eq!((p.rate, p.gains.kp), (5.0, 9.0));
    }
}
