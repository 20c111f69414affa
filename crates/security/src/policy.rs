//! The two documents of DDS-Security's builtin access control (DDS-Security 1.1 §9.4.1.2 governance,
//! §9.4.1.3 permissions) as sros2 writes them.
//!
//! The governance is sros2's default (`sros2/policy/defaults/dds/governance.xml`, Apache-2.0, by Open
//! Source Robotics Foundation): unauthenticated participants refused, join access control on, discovery
//! and liveliness encrypted, every RTPS message signed, and for every topic read and write access
//! controlled with its data and metadata encrypted.
//!
//! A [`Grant`] is what one enclave's participant may publish and subscribe, in DDS topic names: a ROS
//! topic `/a/b` is `rt/a/b`; a service `/s` is two topics, `rq/sRequest` (the client writes it, the
//! server reads it) and `rr/sReply` (the other way); an action `/x` is three services
//! (`/x/_action/send_goal`, `cancel_goal`, `get_result`) and two topics (`/x/_action/feedback`,
//! `status`) its server writes (ros2/design, "Topic and Service name mapping to DDS"; "Actions").

use std::collections::BTreeSet;
use std::fmt::Write as _;

/// The governance document for `domain` (sros2's default).
pub fn governance(domain: u32) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>
        <id>{domain}</id>
      </domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"#
    )
}

/// What one enclave may publish and subscribe, as DDS topic names or fnmatch patterns of them.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Grant {
    pub publish: BTreeSet<String>,
    pub subscribe: BTreeSet<String>,
}

impl Grant {
    /// sros2's default policy for an enclave it knows nothing of: every topic, service and action of
    /// the domain, both ways (and ROS 2's graph topic).
    pub fn everything() -> Self {
        let all: BTreeSet<String> =
            ["rt/*", "rq/*", "rr/*", "ros_discovery_info"].into_iter().map(str::to_owned).collect();
        Grant { publish: all.clone(), subscribe: all }
    }

    /// What every ROS 2 node's participant writes and reads whatever it does: the graph topic, its log,
    /// parameter events, and the answers to parameter requests of nodes named `node_pattern` (`*`: any).
    pub fn node_basics(&mut self, node: &str) -> &mut Self {
        self.both("ros_discovery_info");
        self.publish("rt/rosout");
        self.both("rt/parameter_events");
        // Its own parameter services: it serves them.
        self.server(&format!("/{}/*", node.trim_start_matches('/')));
        self
    }

    pub fn publish(&mut self, dds_name: &str) -> &mut Self {
        self.publish.insert(dds_name.to_owned());
        self
    }

    pub fn subscribe(&mut self, dds_name: &str) -> &mut Self {
        self.subscribe.insert(dds_name.to_owned());
        self
    }

    fn both(&mut self, dds_name: &str) -> &mut Self {
        self.publish(dds_name).subscribe(dds_name)
    }

    /// Writes the ROS topic `name`.
    pub fn writes(&mut self, name: &str) -> &mut Self {
        self.publish(&topic(name))
    }

    /// Reads the ROS topic `name`.
    pub fn reads(&mut self, name: &str) -> &mut Self {
        self.subscribe(&topic(name))
    }

    /// Serves the ROS service `name`.
    pub fn server(&mut self, name: &str) -> &mut Self {
        let (request, reply) = service(name);
        self.subscribe(&request).publish(&reply)
    }

    /// Calls the ROS service `name`.
    pub fn client(&mut self, name: &str) -> &mut Self {
        let (request, reply) = service(name);
        self.publish(&request).subscribe(&reply)
    }

    /// Serves the ROS action `name`.
    pub fn action_server(&mut self, name: &str) -> &mut Self {
        for s in ACTION_SERVICES {
            self.server(&format!("{name}/_action/{s}"));
        }
        for t in ACTION_TOPICS {
            self.writes(&format!("{name}/_action/{t}"));
        }
        self
    }

    /// Sends goals to the ROS action `name` and follows them.
    pub fn action_client(&mut self, name: &str) -> &mut Self {
        for s in ACTION_SERVICES {
            self.client(&format!("{name}/_action/{s}"));
        }
        for t in ACTION_TOPICS {
            self.reads(&format!("{name}/_action/{t}"));
        }
        self
    }

    /// Whether this grant lets its holder publish the DDS topic `dds_name` (fnmatch as the access
    /// control plugins match).
    pub fn may_publish(&self, dds_name: &str) -> bool {
        self.publish.iter().any(|p| fnmatch(p, dds_name))
    }

    pub fn may_subscribe(&self, dds_name: &str) -> bool {
        self.subscribe.iter().any(|p| fnmatch(p, dds_name))
    }

    /// The permissions document of `enclave` with this grant on `domain`, valid over
    /// [`not_before`, `not_after`] (ISO 8601, the enclave certificate's validity, as sros2 copies it).
    pub fn permissions(&self, enclave: &str, domain: u32, not_before: &str, not_after: &str) -> String {
        let e = |s: &str| quick_xml::escape::escape(s).into_owned();
        let mut out = String::new();
        let _ = write!(
            out,
            r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="{name}">
      <subject_name>CN={name}</subject_name>
      <validity>
        <not_before>{not_before}</not_before>
        <not_after>{not_after}</not_after>
      </validity>
      <allow_rule>
        <domains>
          <id>{domain}</id>
        </domains>
"#,
            name = e(enclave),
            not_before = e(not_before),
            not_after = e(not_after),
        );
        for (what, names) in [("publish", &self.publish), ("subscribe", &self.subscribe)] {
            if names.is_empty() {
                continue;
            }
            let _ = writeln!(out, "        <{what}>\n          <topics>");
            for n in names {
                let _ = writeln!(out, "            <topic>{}</topic>", e(n));
            }
            let _ = writeln!(out, "          </topics>\n        </{what}>");
        }
        out.push_str("      </allow_rule>\n      <default>DENY</default>\n    </grant>\n  </permissions>\n</dds>\n");
        out
    }
}

const ACTION_SERVICES: [&str; 3] = ["send_goal", "cancel_goal", "get_result"];
const ACTION_TOPICS: [&str; 2] = ["feedback", "status"];

/// The DDS topic of the ROS topic `name`.
pub fn topic(name: &str) -> String {
    format!("rt/{}", name.trim_start_matches('/'))
}

/// The request and reply DDS topics of the ROS service `name`.
pub fn service(name: &str) -> (String, String) {
    let n = name.trim_start_matches('/');
    (format!("rq/{n}Request"), format!("rr/{n}Reply"))
}

/// fnmatch(3) without flags for `*`, `?` and literal characters (what a permissions document's topic
/// expressions use; `[...]` sets are matched literally, and no grant here writes one).
pub fn fnmatch(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    let (mut i, mut j, mut star, mut mark) = (0, 0, None, 0);
    while j < n.len() {
        if i < p.len() && (p[i] == '?' || p[i] == n[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some(i);
            mark = j;
            i += 1;
        } else if let Some(s) = star {
            i = s + 1;
            mark += 1;
            j = mark;
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros_names_map_to_dds_topics_as_ros2_design_has_them() {
        assert_eq!(topic("/lwr/joint_states"), "rt/lwr/joint_states");
        assert_eq!(
            service("/ft_sensor/bias"),
            ("rq/ft_sensor/biasRequest".to_owned(), "rr/ft_sensor/biasReply".to_owned())
        );
        let mut g = Grant::default();
        g.action_client("/deformation_controller/press");
        assert!(g.may_publish("rq/deformation_controller/press/_action/send_goalRequest"));
        assert!(g.may_subscribe("rt/deformation_controller/press/_action/feedback"));
        assert!(!g.may_publish("rt/deformation_controller/press/_action/status"));
        assert!(!g.may_subscribe("rq/deformation_controller/press/_action/send_goalRequest"));
    }

    #[test]
    fn fnmatch_matches_stars_and_single_characters_and_nothing_else() {
        assert!(fnmatch("*", "rt/a/b"));
        assert!(fnmatch("rq/lwr_driver/*", "rq/lwr_driver/get_parametersRequest"));
        assert!(!fnmatch("rq/lwr_driver/*", "rq/lwr_driver2/get_parametersRequest"));
        assert!(fnmatch("rt/?wr/*_states", "rt/lwr/joint_states"));
        assert!(!fnmatch("rt/lwr", "rt/lwr/joint_states"));
        assert!(fnmatch("a*b*c", "aXXbYYc") && !fnmatch("a*b*c", "aXXbYY"));
    }

    #[test]
    fn a_node_serves_its_own_parameters_and_no_one_elses() {
        let mut g = Grant::default();
        g.node_basics("/contact_estimator");
        assert!(g.may_subscribe("rq/contact_estimator/set_parametersRequest"));
        assert!(g.may_publish("rr/contact_estimator/set_parametersReply"));
        assert!(!g.may_publish("rq/contact_estimator/set_parametersRequest"));
        assert!(!g.may_subscribe("rq/lwr_driver/set_parametersRequest"));
        assert!(g.may_publish("rt/rosout") && !g.may_subscribe("rt/rosout"));
    }

    #[test]
    fn the_permissions_document_lists_the_grant_and_denies_the_rest() {
        let mut g = Grant::default();
        g.writes("/a").reads("/b<c>");
        let xml = g.permissions("/user", 7, "2026-01-01T00:00:00", "2036-01-01T00:00:00");
        assert!(xml.contains("<subject_name>CN=/user</subject_name>"));
        assert!(xml.contains("<id>7</id>"));
        assert!(xml.contains("<publish>\n          <topics>\n            <topic>rt/a</topic>"));
        assert!(xml.contains("<topic>rt/b&lt;c&gt;</topic>"), "{xml}");
        assert!(xml.trim_end().ends_with("<default>DENY</default>\n    </grant>\n  </permissions>\n</dds>"));
        let governance = governance(7);
        assert!(governance.contains("<id>7</id>") && governance.contains("<rtps_protection_kind>SIGN"));
    }
}
