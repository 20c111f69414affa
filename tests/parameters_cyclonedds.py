"""A Cyclone DDS peer asks a node for its parameters, as `ros2 param list/get/describe` over rmw_cyclonedds
would.

rmw_cyclonedds maps a service request to the topic rq/<node>/<service>Request and prefixes each
request and reply with its own header — the client's id (8 bytes) and a sequence number (int64) —
which the server echoes in its reply. The node must answer in that mapping (ros2-client 0.12.1 served
its parameter services with the Fast DDS mapping only: vendor/ros2-client/VENDORED.md).

Usage: parameters_cyclonedds.py NODE NAME=VALUE...   (inside the graph's network namespace)
Checks that list_parameters names every NAME, get_parameters returns each VALUE (a float), and
describe_parameters gives each a description, read-only, and a floating-point range holding VALUE.
"""

import os
import random
import sys
import time
from dataclasses import dataclass

os.environ.setdefault(
    "CYCLONEDDS_URI",
    "<CycloneDDS><Domain><General><Interfaces><NetworkInterface name='lo' multicast='true'/>"
    "</Interfaces></General></Domain></CycloneDDS>",
)

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import float64, int64, sequence, uint8, uint64  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402


@dataclass
class ListParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::ListParameters_Request_"):
    client: uint64  # rmw_cyclonedds' request header
    sequence_number: int64
    prefixes: sequence[str]
    depth: uint64


@dataclass
class ListParametersResult(IdlStruct, typename="rcl_interfaces::msg::dds_::ListParametersResult_"):
    names: sequence[str]
    prefixes: sequence[str]


@dataclass
class ListParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::ListParameters_Response_"):
    client: uint64
    sequence_number: int64
    result: ListParametersResult


@dataclass
class GetParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameters_Request_"):
    client: uint64
    sequence_number: int64
    names: sequence[str]


@dataclass
class ParameterValue(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterValue_"):
    type: uint8
    bool_value: bool
    integer_value: int64
    double_value: float64
    string_value: str
    byte_array_value: sequence[uint8]
    bool_array_value: sequence[bool]
    integer_array_value: sequence[int64]
    double_array_value: sequence[float64]
    string_array_value: sequence[str]


@dataclass
class GetParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameters_Response_"):
    client: uint64
    sequence_number: int64
    values: sequence[ParameterValue]


@dataclass
class DescribeParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::DescribeParameters_Request_"):
    client: uint64
    sequence_number: int64
    names: sequence[str]


@dataclass
class FloatingPointRange(IdlStruct, typename="rcl_interfaces::msg::dds_::FloatingPointRange_"):
    from_value: float64
    to_value: float64
    step: float64


@dataclass
class IntegerRange(IdlStruct, typename="rcl_interfaces::msg::dds_::IntegerRange_"):
    from_value: int64
    to_value: int64
    step: uint64


@dataclass
class ParameterDescriptor(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterDescriptor_"):
    name: str
    type: uint8
    description: str
    additional_constraints: str
    read_only: bool
    dynamic_typing: bool
    floating_point_range: sequence[FloatingPointRange]
    integer_range: sequence[IntegerRange]


@dataclass
class DescribeParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::DescribeParameters_Response_"):
    client: uint64
    sequence_number: int64
    descriptors: sequence[ParameterDescriptor]


def call(dp, node, service, request_type, response_type, request, seconds=10.0):
    """One request in rmw_cyclonedds' mapping; the reply whose header echoes ours."""
    qos = Qos(Policy.Reliability.Reliable(1_000_000_000), Policy.History.KeepLast(10))
    writer = DataWriter(dp, Topic(dp, f"rq/{node}/{service}Request", request_type), qos=qos)
    reader = DataReader(dp, Topic(dp, f"rr/{node}/{service}Reply", response_type), qos=qos)
    deadline = time.time() + seconds
    # Until the server is matched (discovery), then the request again now and then.
    next_send = 0.0
    while time.time() < deadline:
        if time.time() >= next_send:
            writer.write(request)
            next_send = time.time() + 1.0
        for reply in reader.take(N=10):
            if (reply.client, reply.sequence_number) == (request.client, request.sequence_number):
                return reply
        time.sleep(0.02)
    sys.exit(f"no answer from {node}/{service} in {seconds} s (Cyclone DDS request mapping)")


def main():
    node, expected = sys.argv[1], dict(a.split("=", 1) for a in sys.argv[2:])
    dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    client = random.getrandbits(63)
    listed = call(
        dp, node, "list_parameters", ListParametersRequest, ListParametersResponse,
        ListParametersRequest(client=client, sequence_number=1, prefixes=[], depth=0),
    ).result.names
    missing = [n for n in expected if n not in listed]
    if missing:
        sys.exit(f"list_parameters of {node} lacks {missing}: {listed}")
    values = call(
        dp, node, "get_parameters", GetParametersRequest, GetParametersResponse,
        GetParametersRequest(client=client, sequence_number=2, names=list(expected)),
    ).values
    for (name, want), got in zip(expected.items(), values):
        if got.type != 3 or abs(got.double_value - float(want)) > 1e-9:  # 3: PARAMETER_DOUBLE
            sys.exit(f"{node} {name}: type {got.type}, value {got.double_value}, expected {want}")
    described = call(
        dp, node, "describe_parameters", DescribeParametersRequest, DescribeParametersResponse,
        DescribeParametersRequest(client=client, sequence_number=3, names=list(expected)),
    ).descriptors
    for (name, want), d in zip(expected.items(), described):
        ranges = d.floating_point_range
        if d.name != name or d.type != 3 or not d.read_only or not d.description or "missing" in d.description:
            sys.exit(f"{node} {name}: descriptor {d}")
        if len(ranges) != 1 or not ranges[0].from_value <= float(want) <= ranges[0].to_value:
            sys.exit(f"{node} {name}: range {ranges} does not hold {want}")
    print(f"cyclone peer: {node} lists {len(listed)} parameters; {dict(zip(expected, [v.double_value for v in values]))}")
    for d in described:
        r = d.floating_point_range[0]
        print(f"  {d.name}: {d.description} [{r.from_value}, {r.to_value}] {d.additional_constraints}")


if __name__ == "__main__":
    main()
