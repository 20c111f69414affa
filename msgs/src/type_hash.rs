//! REP-2016 type hashes (`RIHS01_…`), which ROS 2 Iron and later announce with every endpoint
//! (`typehash=…;` in its USER_DATA) and `ros2 topic info -v` shows: the SHA-256 of the canonical JSON of
//! the type's description — its fields (name; type id, capacities, nested type name), then every type
//! it refers to, sorted by name — as `rosidl_generator_type_description` writes it. The descriptions are
//! read from the same .msg files as the types (the `ros2msg` definitions of [`crate::definition`]);
//! constants and default values are not part of a description.

use std::collections::BTreeMap;

use sha2::{Digest, Sha256};

/// The hash of the message type `pkg/msg/Name`, or `None` if the project has no definition of it.
pub fn rihs01(type_path: &str) -> Option<String> {
    let mut sections = sections(crate::definition(type_path)?).into_iter();
    let (_, own) = sections.next()?;
    let known: BTreeMap<String, String> = sections.collect();
    hash(&qualified(type_path), &own, &known)
}

/// The hash of the service `pkg/srv/Name` whose .srv text is `srv` (an action's `pkg/action/Name_SendGoal`
/// and `Name_GetResult` are services too: [`action_rihs01`]). Its description is that of the three messages ROS 2
/// generates for it — `Name_Request`, `Name_Response` and `Name_Event` (the service_msgs/ServiceEventInfo
/// and at most one of each) — as `rosidl_generator_type_description` writes it. `local` holds the
/// texts of types that have no .msg here (an action's goal, result and feedback); `None` if a type
/// the service refers to is unknown.
pub fn service_rihs01(service: &str, srv: &str, local: &BTreeMap<String, String>) -> Option<String> {
    let srv = format!("\n{srv}");
    let (request, response) = srv.split_once("\n---").unwrap_or((&srv, ""));
    let mut known = local.clone();
    known.insert(format!("{service}_Request"), request.to_owned());
    known.insert(format!("{service}_Response"), response.trim_start_matches('-').to_owned());
    known.insert(
        format!("{service}_Event"),
        format!(
            "service_msgs/ServiceEventInfo info\n{service}_Request[<=1] request\n{service}_Response[<=1] response\n"
        ),
    );
    let root = format!(
        "{service}_Request request_message\n{service}_Response response_message\n{service}_Event event_message\n"
    );
    hash(service, &root, &known)
}

/// The hashes of the endpoints of the action `pkg/action/Name` (its .action text `text`): the goal and
/// result services and the feedback topic, as ROS 2 generates them from the action. (Its cancel
/// service and status topic have action_msgs' types.)
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ActionHashes {
    pub send_goal: String,
    pub get_result: String,
    pub feedback_message: String,
}

pub fn action_rihs01(action: &str, text: &str) -> Option<ActionHashes> {
    let text = format!("\n{text}");
    let mut parts = text.split("\n---").map(|p| p.trim_start_matches('-').to_owned());
    let local: BTreeMap<String, String> = ["Goal", "Result", "Feedback"]
        .into_iter()
        .map(|part| (format!("{action}_{part}"), parts.next().unwrap_or_default()))
        .collect();
    let goal_id = "unique_identifier_msgs/UUID goal_id\n";
    Some(ActionHashes {
        send_goal: service_rihs01(
            &format!("{action}_SendGoal"),
            &format!("{goal_id}{action}_Goal goal\n---\nbool accepted\nbuiltin_interfaces/Time stamp\n"),
            &local,
        )?,
        get_result: service_rihs01(
            &format!("{action}_GetResult"),
            &format!("{goal_id}---\nint8 status\n{action}_Result result\n"),
            &local,
        )?,
        feedback_message: hash(
            &format!("{action}_FeedbackMessage"),
            &format!("{goal_id}{action}_Feedback feedback\n"),
            &local,
        )?,
    })
}

/// The hash of std_srvs/srv/Trigger (the bias and retare services).
pub fn trigger() -> Option<String> {
    service_rihs01("std_srvs/srv/Trigger", include_str!("../std/std_srvs/Trigger.srv"), &BTreeMap::new())
}

/// The hashes of the controller's force action, softcontact_msgs/action/PressForce.
pub fn press_force() -> Option<ActionHashes> {
    action_rihs01("softcontact_msgs/action/PressForce", include_str!("../action/PressForce.action"))
}

/// SHA-256 of the description's canonical JSON: `name`'s fields from `text`, then every type it refers
/// to, found in `known` or in the project's definitions, sorted by name.
fn hash(name: &str, text: &str, known: &BTreeMap<String, String>) -> Option<String> {
    let mut referenced = BTreeMap::new();
    refer(name, text, known, &mut referenced)?;
    let root = describe(name, text);
    let others: Vec<String> = referenced.iter().map(|(n, t)| describe(n, t)).collect();
    let json = format!("{{\"type_description\": {}, \"referenced_type_descriptions\": [{}]}}", root, others.join(", "));
    let digest = Sha256::digest(json.as_bytes());
    Some(digest.iter().fold(String::from("RIHS01_"), |mut s, b| {
        s.push_str(&format!("{b:02x}"));
        s
    }))
}

/// Adds every type `text` (the fields of `name`) refers to, and theirs, to `out`; `None` if one is
/// unknown.
fn refer(name: &str, text: &str, known: &BTreeMap<String, String>, out: &mut BTreeMap<String, String>) -> Option<()> {
    let package = name.split('/').next().unwrap_or("");
    for line in text.lines() {
        let Some(nested) = parse(package, line).map(|f| f.nested).filter(|n| !n.is_empty()) else { continue };
        if out.contains_key(&nested) {
            continue;
        }
        let text = match known.get(&nested) {
            Some(text) => text.clone(),
            None => sections(crate::definition(&nested)?).into_iter().next()?.1,
        };
        out.insert(nested.clone(), text.clone());
        refer(&nested, &text, known, out)?;
    }
    Some(())
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
/// A type without fields has the one rosidl gives it, `uint8 structure_needs_at_least_one_member`.
fn describe(name: &str, text: &str) -> String {
    let package = name.split('/').next().unwrap_or("");
    let mut fields: Vec<Field> = text.lines().filter_map(|line| parse(package, line)).collect();
    if fields.is_empty() {
        fields = parse(package, "uint8 structure_needs_at_least_one_member").into_iter().collect();
    }
    let fields: Vec<String> = fields.iter().map(Field::json).collect();
    format!("{{\"type_name\": \"{name}\", \"fields\": [{}]}}", fields.join(", "))
}

/// A field of a type description.
struct Field {
    name: String,
    type_id: u32,
    capacity: u64,
    string_capacity: u64,
    /// The nested type's full name, empty for a primitive.
    nested: String,
}

impl Field {
    fn json(&self) -> String {
        format!(
            "{{\"name\": \"{}\", \"type\": {{\"type_id\": {}, \"capacity\": {}, \"string_capacity\": {}, \"nested_type_name\": \"{}\"}}}}",
            self.name, self.type_id, self.capacity, self.string_capacity, self.nested
        )
    }
}

/// A field line of a type in `package`; `None` for blank lines, comments and constants.
fn parse(package: &str, line: &str) -> Option<Field> {
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
    Some(Field { name: name.to_owned(), type_id: id + offset, capacity, string_capacity, nested })
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

    // The service and action hashes ROS 2 Jazzy ships (the `type_hashes` of the packages' generated
    // type descriptions, as other implementations list them).
    #[test]
    fn services_have_their_published_hashes_an_empty_request_included() {
        let none = BTreeMap::new();
        let trigger = include_str!("../std/std_srvs/Trigger.srv");
        assert_eq!(
            service_rihs01("std_srvs/srv/Trigger", trigger, &none).unwrap(),
            "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f"
        );
        let cancel = include_str!("../std/action_msgs/CancelGoal.srv");
        assert_eq!(
            service_rihs01("action_msgs/srv/CancelGoal", cancel, &none).unwrap(),
            "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a"
        );
    }

    #[test]
    fn an_actions_goal_result_and_feedback_have_their_published_hashes() {
        let fibonacci = "int32 order\n---\nint32[] sequence\n---\nint32[] partial_sequence\n";
        let hashes = action_rihs01("action_tutorials_interfaces/action/Fibonacci", fibonacci).unwrap();
        assert_eq!(hashes.send_goal, "RIHS01_a0603060ed69fe2dfbd1a6f3b982a1749957ef346e4a4d2b311a05e305ec37bb");
        assert_eq!(hashes.get_result, "RIHS01_8b47e383f1e31f6d8df6417ab54957e7d5ea24dad315646ad711ac3fdea81d58");
        assert_eq!(hashes.feedback_message, "RIHS01_50fc26b9cac313652ecbeab3adf9b5414d59fd4d4d5f9058ddcc7525169927f1");
    }

    #[test]
    fn field_lines_map_to_type_ids_with_their_capacities() {
        let f = |l| parse("pkg", l).unwrap().json();
        assert!(f("float64[] x").contains("\"type_id\": 155, \"capacity\": 0"));
        assert!(f("int32[3] x").contains("\"type_id\": 54, \"capacity\": 3"));
        assert!(f("string<=5[<=4] x").contains("\"type_id\": 117, \"capacity\": 4, \"string_capacity\": 5"));
        assert!(f("Other[] x  # c").contains(
            "\"type_id\": 145, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"pkg/msg/Other\""
        ));
        assert!(parse("pkg", "uint8 KIND=1").is_none() && parse("pkg", "# x").is_none());
    }
}
