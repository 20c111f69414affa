//! ROS 2 names as `ros2 run … --ros-args -r` sets them: a node's name (`-r __node:=NAME`), its namespace
//! (`-r __ns:=/NS`) and topic and service remapping (`-r FROM:=TO`). A rule without a node prefix is for
//! every node of the process; `-r NODE:FROM:=TO` is for the node named NODE only.
//!
//! The suite's topics and services are named relative to the node's namespace — with the default `/` they
//! are the names in `softcontact_msgs::topics` — except the graph-wide ones ([`GLOBAL`]), which are
//! absolute in ROS 2 too. A rule's FROM and TO are resolved the same way (relative to the namespace,
//! `~/x` below the node) and a rule applies where FROM equals the name resolved; the first such rule wins.

/// Names that stay where they are whatever the namespace: tf2's frames, the simulated clock and the
/// diagnostics aggregator's input.
pub const GLOBAL: [&str; 4] = [topics::TF.name, topics::TF_STATIC.name, topics::CLOCK.name, topics::DIAGNOSTICS.name];

use softcontact_msgs::topics;

/// One node's names: what the command line set, checked.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Remapping {
    /// `__node`: the node's name instead of its own.
    pub node: Option<String>,
    /// `__ns`: the node's namespace instead of `/`.
    pub namespace: Option<String>,
    /// `FROM:=TO`, each side as written.
    pub rules: Vec<(String, String)>,
}

impl Remapping {
    /// The rules of `args` (each `FROM:=TO` or `NODE:FROM:=TO`) that apply to the node named `node`.
    pub fn parse(node: &str, args: &[String]) -> Result<Self, String> {
        let mut out = Remapping::default();
        for arg in args {
            let bad =
                |why: &str| format!("remapping `{arg}`: {why} (FROM:=TO, NODE:FROM:=TO, __node:=NAME or __ns:=/NS)");
            let (left, to) = arg.split_once(":=").ok_or_else(|| bad("no `:=`"))?;
            let (target, from) = match left.split_once(':') {
                Some((target, from)) => {
                    check_token(target).map_err(|why| bad(&format!("node name: {why}")))?;
                    (Some(target), from)
                }
                None => (None, left),
            };
            match from {
                "__node" | "__name" => check_token(to).map_err(|why| bad(&format!("node name: {why}")))?,
                "__ns" => check_name(to, true).map_err(|why| bad(&format!("namespace: {why}")))?,
                _ => {
                    check_name(from, false).map_err(|why| bad(&format!("FROM: {why}")))?;
                    check_name(to, false).map_err(|why| bad(&format!("TO: {why}")))?;
                }
            }
            if target.is_some_and(|t| t != node) {
                continue;
            }
            match from {
                "__node" | "__name" => out.node = Some(to.to_owned()),
                "__ns" => out.namespace = Some(to.to_owned()).filter(|n| n != "/"),
                _ => out.rules.push((from.to_owned(), to.to_owned())),
            }
        }
        Ok(out)
    }

    /// The node name these rules give a node called `own`.
    pub fn node_name<'a>(&'a self, own: &'a str) -> &'a str {
        self.node.as_deref().unwrap_or(own)
    }

    /// The namespace these rules give a node: `/` unless `__ns` set one.
    pub fn namespace(&self) -> &str {
        self.namespace.as_deref().unwrap_or("/")
    }

    /// The name a topic or service declared as `declared` (absolute, as in `softcontact_msgs::topics`)
    /// has on the graph for the node named `node`.
    pub fn resolve(&self, node: &str, declared: &str) -> String {
        let namespace = self.namespace();
        let name = match GLOBAL.contains(&declared) {
            true => declared.to_owned(),
            false => format!("{}/{}", namespace.trim_end_matches('/'), declared.trim_start_matches('/')),
        };
        for (from, to) in &self.rules {
            if qualify(namespace, node, from) == name {
                return qualify(namespace, node, to);
            }
        }
        name
    }
}

/// A name from the command line fully qualified as ROS 2 does: `~/x` below the node, `/x` as it is, `x`
/// below the namespace.
fn qualify(namespace: &str, node: &str, name: &str) -> String {
    let ns = namespace.trim_end_matches('/');
    match name.strip_prefix('~') {
        Some(private) => format!("{ns}/{node}{private}"),
        None if name.starts_with('/') => name.to_owned(),
        None => format!("{ns}/{name}"),
    }
}

/// A name token: a letter or `_`, then letters, digits and `_`.
fn check_token(token: &str) -> Result<(), String> {
    let mut chars = token.chars();
    match chars.next() {
        None => Err("empty".into()),
        Some(c) if !(c.is_ascii_alphabetic() || c == '_') => Err(format!("`{token}` must start with a letter or `_`")),
        _ if chars.all(|c| c.is_ascii_alphanumeric() || c == '_') => Ok(()),
        _ => Err(format!("`{token}` may hold only letters, digits and `_`")),
    }
}

/// A topic or service name (`a/b`, `/a/b`, `~/a`), or with `absolute` a namespace (`/a/b`).
fn check_name(name: &str, absolute: bool) -> Result<(), String> {
    if absolute && !name.starts_with('/') {
        return Err(format!("`{name}` must start with `/`"));
    }
    if absolute && name == "/" {
        return Ok(());
    }
    let body = name.strip_prefix("~/").or_else(|| name.strip_prefix('/')).unwrap_or(name);
    body.split('/').try_for_each(check_token)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rules(args: &[&str], node: &str) -> Remapping {
        Remapping::parse(node, &args.iter().map(|a| a.to_string()).collect::<Vec<_>>()).unwrap()
    }

    #[test]
    fn without_rules_every_name_is_the_declared_one() {
        let r = rules(&[], "lwr_driver");
        for name in ["/lwr/joint_states", "/tf", "/clock", "/ft_sensor/bias"] {
            assert_eq!(r.resolve("lwr_driver", name), name);
        }
        assert_eq!((r.node_name("lwr_driver"), r.namespace()), ("lwr_driver", "/"));
    }

    #[test]
    fn a_namespace_moves_the_suites_names_and_leaves_tf_clock_and_diagnostics() {
        let r = rules(&["__ns:=/cell2"], "lwr_driver");
        assert_eq!(r.resolve("lwr_driver", "/lwr/joint_states"), "/cell2/lwr/joint_states");
        assert_eq!(r.resolve("lwr_driver", "/robot_description"), "/cell2/robot_description");
        for global in GLOBAL {
            assert_eq!(r.resolve("lwr_driver", global), global);
        }
    }

    #[test]
    fn a_rule_matches_the_resolved_name_written_either_way_and_the_first_wins() {
        let r = rules(&["/lwr/joint_states:=/joint_states", "lwr/joint_states:=/other"], "lwr_driver");
        assert_eq!(r.resolve("lwr_driver", "/lwr/ee_pose"), "/lwr/ee_pose");
        assert_eq!(r.resolve("lwr_driver", "/lwr/joint_states"), "/joint_states");
        let r = rules(&["__ns:=/a", "lwr/joint_states:=js", "/lwr/ee_pose:=/x"], "lwr_driver");
        assert_eq!(r.resolve("lwr_driver", "/lwr/joint_states"), "/a/js");
        // An absolute FROM names the absolute name, which the namespace moved away from.
        assert_eq!(r.resolve("lwr_driver", "/lwr/ee_pose"), "/a/lwr/ee_pose");
        let r = rules(&["/tf:=/tf_cell2", "~/state:=~/s"], "deformation_controller");
        assert_eq!(r.resolve("deformation_controller", "/tf"), "/tf_cell2");
        assert_eq!(r.resolve("deformation_controller", "/deformation_controller/state"), "/deformation_controller/s");
    }

    #[test]
    fn a_rule_with_a_node_prefix_is_for_that_node_only() {
        let args = ["ft_sensor:__node:=box", "lwr_driver:__ns:=/arm", "ft_sensor:/ft_sensor/wrench:=/w"];
        let ft = rules(&args, "ft_sensor");
        assert_eq!((ft.node_name("ft_sensor"), ft.namespace()), ("box", "/"));
        assert_eq!(ft.resolve("box", "/ft_sensor/wrench"), "/w");
        let driver = rules(&args, "lwr_driver");
        assert_eq!((driver.node_name("lwr_driver"), driver.namespace()), ("lwr_driver", "/arm"));
        assert_eq!(driver.resolve("lwr_driver", "/ft_sensor/wrench"), "/arm/ft_sensor/wrench");
    }

    #[test]
    fn malformed_rules_are_refused_with_the_form_they_take() {
        let bad = [
            "joint_states",
            "__ns:=cell",
            "__ns:=/cell/",
            "__node:=my-node",
            "a//b:=c",
            "/a:=",
            "9x:=y",
            "n-1:a:=b",
            "a:=b c",
        ];
        for arg in bad {
            let e = Remapping::parse("x", &[arg.to_string()]).unwrap_err();
            assert!(e.contains(arg) && e.contains("FROM:=TO"), "{arg}: {e}");
        }
    }
}
