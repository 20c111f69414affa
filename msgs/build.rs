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

fn main() {
    println!("cargo:rerun-if-changed=msg");
    let mut files: Vec<_> = std::fs::read_dir("msg").expect("msg/").map(|e| e.expect("entry").path()).collect();
    files.sort();
    let mut out = String::new();
    for path in files.iter().filter(|p| p.extension().is_some_and(|e| e == "msg")) {
        let name = path.file_stem().unwrap().to_str().unwrap();
        let text = std::fs::read_to_string(path).unwrap();
        let doc: Vec<&str> =
            text.lines().take_while(|l| l.starts_with('#')).map(|l| l.trim_start_matches('#').trim()).collect();
        writeln!(out, "/// {}\n#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]\npub struct {name} {{", doc.join(" ")).unwrap();
        for line in text.lines() {
            let (field, comment) = line.split_once('#').unwrap_or((line, ""));
            let mut parts = field.split_whitespace();
            let (Some(ty), Some(field_name)) = (parts.next(), parts.next()) else { continue };
            if !comment.trim().is_empty() {
                writeln!(out, "    /// {}", comment.trim()).unwrap();
            }
            writeln!(out, "    pub {field_name}: {},", rust_type(ty)).unwrap();
        }
        writeln!(out, "}}\nimpl ros2_client::Message for {name} {{}}\nimpl crate::RosType for {name} {{\n    const PACKAGE: &'static str = \"softcontact_msgs\";\n    const NAME: &'static str = \"{name}\";\n}}\n").unwrap();
    }
    std::fs::write(std::path::Path::new(&std::env::var("OUT_DIR").unwrap()).join("softcontact_msgs.rs"), out).unwrap();
}
