//! Generates the Rust types of msg/*.msg (one description of each message: the .msg file that rosidl
//! also builds). Supported field types: the ROS 2 primitives, string, unbounded arrays T[], and the
//! message types of this crate's modules (std_msgs/Header, geometry_msgs/Point, …).

use std::fmt::Write;

fn rust_type(ros: &str) -> String {
    if let Some(inner) = ros.strip_suffix("[]") {
        return format!("Vec<{}>", rust_type(inner));
    }
    match ros {
        "bool" => "bool".into(),
        "byte" | "uint8" | "char" => "u8".into(),
        "int8" => "i8".into(),
        "int16" => "i16".into(),
        "uint16" => "u16".into(),
        "int32" => "i32".into(),
        "uint32" => "u32".into(),
        "int64" => "i64".into(),
        "uint64" => "u64".into(),
        "float32" => "f32".into(),
        "float64" => "f64".into(),
        "string" => "String".into(),
        nested => match nested.split_once('/') {
            Some((pkg, name)) => format!("crate::{pkg}::{name}"),
            None => panic!("unsupported field type `{nested}`"),
        },
    }
}

/// Message types a .msg field refers to, as `pkg/Name` (constants and primitives skipped).
fn field_types(package: &str, text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        let field = line.split('#').next().unwrap_or("");
        let mut parts = field.split_whitespace();
        let (Some(ty), Some(name)) = (parts.next(), parts.next()) else { continue };
        let base = ty.split('[').next().unwrap_or(ty);
        if name.contains('=') || base.contains('<') || is_primitive(base) {
            continue;
        }
        out.push(if base.contains('/') { base.to_string() } else { format!("{package}/{base}") });
    }
    out
}

fn is_primitive(ty: &str) -> bool {
    matches!(
        ty,
        "bool"
            | "byte"
            | "char"
            | "int8"
            | "uint8"
            | "int16"
            | "uint16"
            | "int32"
            | "uint32"
            | "int64"
            | "uint64"
            | "float32"
            | "float64"
            | "string"
            | "wstring"
    )
}

/// The definition text ROS 2 stores with a recording (rosbag2, MCAP schema encoding `ros2msg`): the
/// message's own .msg, then each message type it depends on, depth first, once, after a separator line.
fn full_definition(root: &str, texts: &std::collections::BTreeMap<String, String>) -> String {
    fn visit(ty: &str, texts: &std::collections::BTreeMap<String, String>, seen: &mut Vec<String>) {
        let package = ty.split('/').next().unwrap();
        let text = texts.get(ty).unwrap_or_else(|| panic!("no .msg for `{ty}`"));
        for dep in field_types(package, text) {
            if !seen.contains(&dep) {
                seen.push(dep.clone());
                visit(&dep, texts, seen);
            }
        }
    }
    let mut deps = Vec::new();
    visit(root, texts, &mut deps);
    let mut out = texts[root].trim_end().to_string();
    out.push('\n');
    for dep in deps {
        out.push_str(&"=".repeat(80));
        write!(out, "\nMSG: {dep}\n{}\n", texts[&dep].trim_end()).unwrap();
    }
    out
}

/// Every message definition: std/<package>/<Name>.msg (standard ROS 2 types, as common_interfaces
/// defines them) and msg/<Name>.msg (this package), keyed `pkg/Name`.
fn definitions() -> std::collections::BTreeMap<String, String> {
    let mut texts = std::collections::BTreeMap::new();
    let mut add = |package: &str, dir: &std::path::Path| {
        for entry in std::fs::read_dir(dir).expect("message folder") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "msg") {
                let name = path.file_stem().unwrap().to_str().unwrap().to_string();
                texts.insert(format!("{package}/{name}"), std::fs::read_to_string(&path).unwrap());
            }
        }
    };
    for entry in std::fs::read_dir("std").expect("std/") {
        let dir = entry.expect("entry").path();
        add(dir.file_name().unwrap().to_str().unwrap(), &dir);
    }
    add("softcontact_msgs", std::path::Path::new("msg"));
    texts
}

/// A .msg comment as Rust doc text: its brackets (units, lists) escaped, or rustdoc reads them as links.
fn doc_text(comment: &str) -> String {
    comment.replace('[', "\\[").replace(']', "\\]")
}

/// The Rust struct of one message definition (its leading comment lines are its doc).
fn rust_struct(out: &mut String, name: &str, text: &str) {
    let doc: Vec<&str> =
        text.lines().take_while(|l| l.starts_with('#')).map(|l| l.trim_start_matches('#').trim()).collect();
    writeln!(out, "/// {}\n#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]\npub struct {name} {{", doc_text(&doc.join(" "))).unwrap();
    for line in text.lines() {
        let (field, comment) = line.split_once('#').unwrap_or((line, ""));
        let mut parts = field.split_whitespace();
        let (Some(ty), Some(field_name)) = (parts.next(), parts.next()) else { continue };
        if !comment.trim().is_empty() {
            writeln!(out, "    /// {}", doc_text(comment.trim())).unwrap();
        }
        writeln!(out, "    pub {field_name}: {},", rust_type(ty)).unwrap();
    }
    writeln!(out, "}}\nimpl ros2_client::Message for {name} {{}}").unwrap();
}

fn main() {
    println!("cargo:rerun-if-changed=msg");
    println!("cargo:rerun-if-changed=action");
    println!("cargo:rerun-if-changed=std");
    let texts = definitions();
    let mut table = String::from(
        "/// Full ROS 2 definitions (`ros2msg`), keyed by `pkg/msg/Name`.\npub static DEFINITIONS: &[(&str, &str)] = &[\n",
    );
    for ty in texts.keys() {
        let (package, name) = ty.split_once('/').unwrap();
        writeln!(table, "    ({:?}, {:?}),", format!("{package}/msg/{name}"), full_definition(ty, &texts)).unwrap();
    }
    table.push_str("];\n");
    std::fs::write(std::path::Path::new(&std::env::var("OUT_DIR").unwrap()).join("definitions.rs"), table).unwrap();
    let mut files: Vec<_> = std::fs::read_dir("msg").expect("msg/").map(|e| e.expect("entry").path()).collect();
    files.sort();
    let mut out = String::new();
    for path in files.iter().filter(|p| p.extension().is_some_and(|e| e == "msg")) {
        let name = path.file_stem().unwrap().to_str().unwrap();
        rust_struct(&mut out, name, &std::fs::read_to_string(path).unwrap());
        writeln!(out, "impl crate::RosType for {name} {{\n    const PACKAGE: &'static str = \"softcontact_msgs\";\n    const NAME: &'static str = \"{name}\";\n}}\n").unwrap();
    }
    // Actions: action/<Name>.action, goal, result and feedback separated by lines of `---`, as the
    // types <Name>Goal, <Name>Result and <Name>Feedback (rosidl: <Name>_Goal, …).
    let mut actions: Vec<_> = std::fs::read_dir("action").expect("action/").map(|e| e.expect("entry").path()).collect();
    actions.sort();
    for path in actions.iter().filter(|p| p.extension().is_some_and(|e| e == "action")) {
        let name = path.file_stem().unwrap().to_str().unwrap();
        let text = std::fs::read_to_string(path).unwrap();
        let parts: Vec<String> = text.split("\n---\n").map(str::to_string).collect();
        assert_eq!(parts.len(), 3, "{}: goal, result and feedback", path.display());
        for (part, suffix) in parts.iter().zip(["Goal", "Result", "Feedback"]) {
            rust_struct(&mut out, &format!("{name}{suffix}"), part);
        }
    }
    std::fs::write(std::path::Path::new(&std::env::var("OUT_DIR").unwrap()).join("softcontact_msgs.rs"), out).unwrap();
}
