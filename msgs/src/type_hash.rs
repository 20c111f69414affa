//! REP-2016 type hashes (`RIHS01_…`), which ROS 2 Iron and later announce with every endpoint
//! (`typehash=…;` in its USER_DATA) and `ros2 topic info -v` shows: the SHA-256 of the canonical JSON of
//! the type's description — its fields (name; type id, capacities, nested type name), then every type
//! it refers to, sorted by name — as `rosidl_generator_type_description` writes it. The descriptions are
//! read from the same .msg files as the types (the `ros2msg` definitions of [`crate::definition`]);
//! constants and default values are not part of a description.

use sha2::{Digest, Sha256};

/// The hash of the message type `pkg/msg/Name`, or `None` if the project has no definition of it.
pub fn rihs01(type_path: &str) -> Option<String> {
    let mut sections = sections(crate::definition(type_path)?).into_iter();
    let (_, own) = sections.next()?;
    let root = describe(&qualified(type_path), &own);
    let mut referenced: Vec<String> = sections.map(|(name, text)| describe(&name, &text)).collect();
    referenced.sort();
    let json =
        format!("{{\"type_description\": {}, \"referenced_type_descriptions\": [{}]}}", root, referenced.join(", "));
    let digest = Sha256::digest(json.as_bytes());
    Some(digest.iter().fold(String::from("RIHS01_"), |mut s, b| {
        s.push_str(&format!("{b:02x}"));
        s
    }))
}

/// The type's own .msg text (its name empty), then each type it refers to, `(pkg/msg/Name, .msg text)`,
/// from a full definition.
fn sections(definition: &str) -> Vec<(String, String)> {
    let separator = "=".repeat(80);
    let mut out: Vec<(String, String)> = Vec::new();
    for (i, part) in definition.split(&separator).enumerate() {
        if i == 0 {
            out.push((String::new(), part.to_owned()));
            continue;
        }
        let part = part.trim_start_matches('\n');
        let (header, text) = part.split_once('\n').unwrap_or((part, ""));
        let name = header.trim().trim_start_matches("MSG:").trim();
        out.push((qualified(name), text.to_owned()));
    }
    out
}

/// `pkg/Name` or `pkg/msg/Name` as `pkg/msg/Name`.
fn qualified(name: &str) -> String {
    match name.split('/').collect::<Vec<_>>()[..] {
        [package, base] => format!("{package}/msg/{base}"),
        _ => name.to_owned(),
    }
}

/// One type's description as JSON (`type_name`, `fields`); a nested type without a package is in `name`'s.
fn describe(name: &str, text: &str) -> String {
    let package = name.split('/').next().unwrap_or("");
    let fields: Vec<String> = text.lines().filter_map(|line| field(package, line)).collect();
    format!("{{\"type_name\": \"{name}\", \"fields\": [{}]}}", fields.join(", "))
}

/// A field line's description, `None` for blank lines, comments and constants.
fn field(package: &str, line: &str) -> Option<String> {
    let line = line.split('#').next().unwrap_or("").trim();
    let mut parts = line.split_whitespace();
    let (ty, name) = (parts.next()?, parts.next()?);
    if name.contains('=') || line[ty.len()..].trim_start()[name.len()..].trim_start().starts_with('=') {
        return None;
    }
    let (base, suffix) = match ty.split_once('[') {
        Some((base, rest)) => (base, Some(rest.trim_end_matches(']'))),
        None => (ty, None),
    };
    let (offset, capacity) = match suffix {
        None => (0, 0),
        Some("") => (144, 0),
        Some(bound) => match bound.strip_prefix("<=") {
            Some(n) => (96, n.parse().ok()?),
            None => (48, bound.parse().ok()?),
        },
    };
    let (id, string_capacity, nested) = match base.split_once("<=") {
        Some(("string", n)) => (21, n.parse().ok()?, String::new()),
        Some(("wstring", n)) => (22, n.parse().ok()?, String::new()),
        _ => match primitive(base) {
            Some(id) => (id, 0u64, String::new()),
            None if base.contains('/') => (1, 0, qualified(base)),
            None => (1, 0, format!("{package}/msg/{base}")),
        },
    };
    Some(format!(
        "{{\"name\": \"{name}\", \"type\": {{\"type_id\": {}, \"capacity\": {capacity}, \"string_capacity\": {string_capacity}, \"nested_type_name\": \"{nested}\"}}}}",
        id + offset
    ))
}

/// `type_description_interfaces/msg/FieldType` ids of the .msg primitives (`char` is a uint8 in ROS 2).
fn primitive(ty: &str) -> Option<u32> {
    Some(match ty {
        "int8" => 2,
        "uint8" | "char" => 3,
        "int16" => 4,
        "uint16" => 5,
        "int32" => 6,
        "uint32" => 7,
        "int64" => 8,
        "uint64" => 9,
        "float32" => 10,
        "float64" => 11,
        "bool" => 15,
        "byte" => 16,
        "string" => 17,
        "wstring" => 18,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn std_msgs_string_has_its_published_hash() {
        // The hash ROS 2 Jazzy ships for std_msgs/msg/String (std_msgs' generated type description).
        assert_eq!(
            rihs01("std_msgs/msg/String").unwrap(),
            "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
        );
    }

    #[test]
    fn field_lines_map_to_type_ids_with_their_capacities() {
        let f = |l| field("pkg", l).unwrap();
        assert!(f("float64[] x").contains("\"type_id\": 155, \"capacity\": 0"));
        assert!(f("int32[3] x").contains("\"type_id\": 54, \"capacity\": 3"));
        assert!(f("string<=5[<=4] x").contains("\"type_id\": 117, \"capacity\": 4, \"string_capacity\": 5"));
        assert!(f("Other[] x  # c").contains(
            "\"type_id\": 145, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"pkg/msg/Other\""
        ));
        assert!(field("pkg", "uint8 KIND=1").is_none() && field("pkg", "# x").is_none());
    }
}
