"""A ROS 2 peer on another DDS implementation (Eclipse Cyclone DDS, Python bindings) reads the graph.

Subscribes to /ft_sensor/wrench (geometry_msgs/msg/WrenchStamped) and /deformation_controller/state
(softcontact_msgs/msg/ControllerState) under their ROS 2 DDS names, as rclpy over rmw_cyclonedds would,
and checks the decoded values: frames, increasing stamps, the force command the test sent, and the
normal force the controller reports against the magnitude of the measured contact force.

Usage: interop_cyclonedds.py EXPECTED_F_CMD [SECONDS]   (run inside the graph's network namespace)
"""

import os
import statistics
import sys
import time
from dataclasses import dataclass

# Loopback only, multicast on: the namespace the launch script made has nothing else.
os.environ.setdefault(
    "CYCLONEDDS_URI",
    "<CycloneDDS><Domain><General><Interfaces><NetworkInterface name='lo' multicast='true'/>"
    "</Interfaces></General></Domain></CycloneDDS>",
)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import float64, int32, uint32  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Wrench(IdlStruct, typename="geometry_msgs::msg::dds_::Wrench_"):
    force: Vector3
    torque: Vector3


@dataclass
class WrenchStamped(IdlStruct, typename="geometry_msgs::msg::dds_::WrenchStamped_"):
    header: Header
    wrench: Wrench


@dataclass
class ControllerState(IdlStruct, typename="softcontact_msgs::msg::dds_::ControllerState_"):
    header: Header
    f_cmd: float64
    z_cmd: float64
    zdot_cmd: float64
    z: float64
    zdot: float64
    f: float64
    f_predicted: float64
    in_contact: bool
    contact_lost: bool
    force_limited: bool


def stamp(h):
    return h.stamp.sec + h.stamp.nanosec * 1e-9


def main():
    expected_f_cmd = float(sys.argv[1])
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 3.0
    dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(100))
    wrenches = DataReader(dp, Topic(dp, "rt/ft_sensor/wrench", WrenchStamped), qos=qos)
    states = DataReader(dp, Topic(dp, "rt/deformation_controller/state", ControllerState), qos=qos)
    got_w, got_s = [], []
    end = time.monotonic() + seconds + 5.0
    first = None
    while time.monotonic() < end:
        got_w += wrenches.take(N=100)
        got_s += states.take(N=100)
        if got_w and got_s and first is None:
            first = time.monotonic()
            end = first + seconds
        time.sleep(0.005)
    print(f"cyclonedds peer: {len(got_w)} WrenchStamped, {len(got_s)} ControllerState")
    assert len(got_w) > 100 * seconds, "1 kHz wrench stream mostly received"
    assert len(got_s) > 20 * seconds, "100 Hz state stream mostly received"
    assert all(w.header.frame_id == "ft_sensor" for w in got_w)
    assert all(s.header.frame_id == "world" for s in got_s)
    for xs in (got_w, got_s):
        ts = [stamp(x.header) for x in xs]
        assert all(b >= a for a, b in zip(ts, ts[1:])), "stamps increase"
        assert ts[0] > 0
    assert all(s.in_contact and not s.contact_lost and not s.force_limited for s in got_s)
    assert all(s.f_cmd == expected_f_cmd for s in got_s), (expected_f_cmd, {s.f_cmd for s in got_s})
    # The controller's normal force is the measured contact force seen from the world: at a hold, its
    # magnitude in the sensor frame is the same number.
    magnitude = statistics.median(
        (w.wrench.force.x ** 2 + w.wrench.force.y ** 2 + w.wrench.force.z ** 2) ** 0.5 for w in got_w
    )
    normal = statistics.median(s.f for s in got_s)
    print(f"cyclonedds peer: |F| {magnitude:.2f} N, controller f {normal:.2f} N, f_cmd {expected_f_cmd} N")
    assert abs(magnitude - normal) < 0.05 * normal + 1.0, (magnitude, normal)
    assert abs(normal - expected_f_cmd) < 0.05 * expected_f_cmd, (normal, expected_f_cmd)
    print("cyclonedds peer: ok")


if __name__ == "__main__":
    main()
