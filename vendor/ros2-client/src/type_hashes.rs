//! REP-2016 type hashes (`RIHS01_…`) of the types ros2-client's own endpoints carry — rosout,
//! parameter events and services, `ros_discovery_info`, `/clock`, the actions' cancel service and
//! status topic — keyed by DDS type name. ROS 2 Jazzy's rmw announces `typehash=<hash>;` in every
//! endpoint's USER_DATA; with the `jazzy` feature the context adds it to these endpoints when the
//! caller's QoS has no USER_DATA of its own. The values are those Jazzy's generated type descriptions
//! carry (the rcl_interfaces services as `zenoh_backend::jazzy_types` computes them; the messages as
//! rosbags' Jazzy type store hashes them).

const HASHES: &[(&str, &str)] = &[
  ("rcl_interfaces::msg::dds_::Log_", "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac"),
  ("rcl_interfaces::msg::dds_::ParameterEvent_", "RIHS01_043e627780fcad87a22d225bc2a037361dba713fca6a6b9f4b869a5aa0393204"),
  ("rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_", "RIHS01_e725f4a506958c79f95dd693b965722c57b19cd18e7eff984f49561b93dc985d"),
  ("rosgraph_msgs::msg::dds_::Clock_", "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"),
  ("action_msgs::msg::dds_::GoalStatusArray_", "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e"),
  ("action_msgs::srv::dds_::CancelGoal_", "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a"),
  ("rcl_interfaces::srv::dds_::GetParameters_", "RIHS01_bf9803d5c74cf989a5de3e0c2e99444599a627c7ff75f97b8c05b01003675cbc"),
  ("rcl_interfaces::srv::dds_::GetParameterTypes_", "RIHS01_da199c878688b3e530bdfe3ca8f74cb9fa0c303101e980a9e8f260e25e1c80ca"),
  ("rcl_interfaces::srv::dds_::SetParameters_", "RIHS01_56eed9a67e169f9cb6c1f987bc88f868c14a8fc9f743a263bc734c154015d7e0"),
  ("rcl_interfaces::srv::dds_::SetParametersAtomically_", "RIHS01_0e192ef259c07fc3c07a13191d27002222e65e00ccec653ca05e856f79285fcd"),
  ("rcl_interfaces::srv::dds_::ListParameters_", "RIHS01_3e6062bfbb27bfb8730d4cef2558221f51a11646d78e7bb30a1e83afac3aad9d"),
  ("rcl_interfaces::srv::dds_::DescribeParameters_", "RIHS01_845b484d71eb0673dae682f2e3ba3c4851a65a3dcfb97bddd82c5b57e91e4cff"),
];

/// The hash of the DDS type `dds_type_name`, if it is one of ros2-client's own; a service's request
/// and response types (`…_Request_`, `…_Response_`) have the service's.
pub fn builtin(dds_type_name: &str) -> Option<&'static str> {
  let service = dds_type_name
    .strip_suffix("_Request_")
    .or_else(|| dds_type_name.strip_suffix("_Response_"))
    .map(|base| format!("{base}_"));
  let name = service.as_deref().unwrap_or(dds_type_name);
  HASHES.iter().find(|(t, _)| *t == name).map(|(_, h)| *h)
}

/// `qos` with `typehash=…;` in its USER_DATA if the topic's type is one of [`builtin`]'s and the QoS
/// has no USER_DATA (Jazzy builds); otherwise `qos` as it is.
#[cfg(feature = "dds")]
pub(crate) fn announced(
  dds_type_name: &str,
  qos: Option<rustdds::QosPolicies>,
) -> Option<rustdds::QosPolicies> {
  let hash = builtin(dds_type_name).filter(|_| cfg!(feature = "jazzy"));
  match (hash, &qos) {
    (Some(_), Some(q)) if q.user_data().is_some() => qos,
    (Some(hash), _) => Some(
      qos
        .unwrap_or_else(rustdds::QosPolicies::qos_none)
        .with_user_data(format!("typehash={hash};").into_bytes()),
    ),
    (None, _) => qos,
  }
}

#[cfg(test)]
mod tests {
  use super::*;

  #[test]
  fn a_services_request_and_response_carry_the_services_hash() {
    let get = "RIHS01_bf9803d5c74cf989a5de3e0c2e99444599a627c7ff75f97b8c05b01003675cbc";
    assert_eq!(builtin("rcl_interfaces::srv::dds_::GetParameters_Request_"), Some(get));
    assert_eq!(builtin("rcl_interfaces::srv::dds_::GetParameters_Response_"), Some(get));
    assert_eq!(builtin("std_msgs::msg::dds_::String_"), None);
  }
}
