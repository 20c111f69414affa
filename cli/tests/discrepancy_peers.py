#!/usr/bin/env python3
"""Recordings for the discrepancy workflow written by peers no one here wrote (pip: mcap-ros2-support,
rosbags), the way a lab's own logger would: a foam pushed by 1 Hz sines at RATE Hz, the wrench stamped
1 ms after the pose, and a relaxation the contact law does not have.

    discrepancy_peers.py write DIR RATE    DIR/by_rosbags (a rosbag2 folder, MCAP storage) and
                                           DIR/by_mcap_ros2.mcap

The force is computed here, independently of the project's code: f = k z^1.5 + lam z^0.5 zdot + s, with a
Maxwell branch ds/dt = K_M zdot - s / TAU (exact update with zdot held over a step) and Gaussian noise.
"""

import math
import pathlib
import random
import sys

from mcap.writer import CompressionType
from mcap_ros2.writer import Writer as McapRos2Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Rosbag2Writer
from rosbags.typesys import Stores, get_typestore

K, LAM = 25_000.0, 1100.0
K_M, TAU = 300.0, 0.5
NOISE = 0.1
SURFACE_Z = 0.3
T0 = 1_700_000_000


def profile(t):
    """Deformation z (into the surface) and its rate: free space, a ramp, 1 Hz pushes, a lift-off."""
    approach, speed, lo, hi = 0.005, 0.01, 0.008, 0.03
    touch = approach / speed
    if t < touch:
        return speed * t - approach, speed
    if t > 18.0:  # the lift-off from the deepest point (z = hi at t = 18 s) at 2 cm/s to 5 mm above
        z = hi - 0.02 * (t - 18.0)
        return (z, -0.02) if z > -0.005 else (-0.005, 0.0)
    s = t - touch
    w = 2 * math.pi
    # From the ramp into the pushes over half a second; the rate is z's own derivative, blend's included.
    blend, blend_rate = (s / 0.5, 1 / 0.5) if s < 0.5 else (1.0, 0.0)
    mid, amp = (lo + hi) / 2, (hi - lo) / 2
    target = mid - amp * math.cos(w * s)
    rate = blend * amp * w * math.sin(w * s) + (1 - blend) * speed + blend_rate * (target - speed * s)
    return blend * target + (1 - blend) * speed * s, rate


def messages(ts, rate):
    """(log time ns, topic, message) in time order."""
    Time = ts.types["builtin_interfaces/msg/Time"]
    Header = ts.types["std_msgs/msg/Header"]
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    Quaternion = ts.types["geometry_msgs/msg/Quaternion"]
    rng = random.Random(5)
    branch = 0.0
    dt = 1.0 / rate
    identity = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    tf = ts.types["tf2_msgs/msg/TFMessage"](
        transforms=[
            ts.types["geometry_msgs/msg/TransformStamped"](
                header=Header(stamp=Time(sec=T0, nanosec=0), frame_id="lwr_tool"),
                child_frame_id="ft_sensor",
                transform=ts.types["geometry_msgs/msg/Transform"](
                    translation=Vector3(x=0.0, y=0.0, z=0.0), rotation=identity
                ),
            )
        ]
    )
    yield T0 * 10**9, "/tf_static", tf
    for i in range(int(20.0 * rate)):
        t = i * dt
        z, zdot = profile(t)
        # The branch: exact over the step with zdot held; it only acts in contact.
        decay = math.exp(-dt / TAU)
        branch = branch * decay + K_M * zdot * TAU * (1 - decay) if z > 0 else 0.0
        force = K * z**1.5 + LAM * math.sqrt(z) * zdot + branch if z > 0 else 0.0
        force = max(force, 0.0) + rng.gauss(0.0, NOISE)
        pose_ns = T0 * 10**9 + round(t * 1e9)
        wrench_ns = pose_ns + 1_000_000  # the sensor's stamp 1 ms after the pose's
        stamp = lambda ns: Time(sec=ns // 10**9, nanosec=ns % 10**9)  # noqa: E731
        world = Header(stamp=stamp(pose_ns), frame_id="world")
        pose = ts.types["geometry_msgs/msg/PoseStamped"](
            header=world,
            pose=ts.types["geometry_msgs/msg/Pose"](
                position=ts.types["geometry_msgs/msg/Point"](x=0.5, y=0.0, z=SURFACE_Z - z), orientation=identity
            ),
        )
        twist = ts.types["geometry_msgs/msg/TwistStamped"](
            header=world,
            twist=ts.types["geometry_msgs/msg/Twist"](
                linear=Vector3(x=0.0, y=0.0, z=-zdot), angular=Vector3(x=0.0, y=0.0, z=0.0)
            ),
        )
        # The force the surface puts on the hand points up (+z); the sensor frame is the tool's, the world's.
        wrench = ts.types["geometry_msgs/msg/WrenchStamped"](
            header=Header(stamp=stamp(wrench_ns), frame_id="ft_sensor"),
            wrench=ts.types["geometry_msgs/msg/Wrench"](
                force=Vector3(x=rng.gauss(0.0, NOISE), y=rng.gauss(0.0, NOISE), z=force),
                torque=Vector3(x=0.0, y=0.0, z=0.0),
            ),
        )
        yield pose_ns, "/lwr/ee_pose", pose
        yield pose_ns, "/lwr/ee_twist", twist
        yield wrench_ns, "/ft_sensor/wrench", wrench


def write(folder, rate):
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ts = get_typestore(Stores.ROS2_JAZZY)
    with Rosbag2Writer(folder / "by_rosbags", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for ns, topic, msg in messages(ts, rate):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=ts)
            writer.write(connections[topic], ns, ts.serialize_cdr(msg, msg.__msgtype__))
    with open(folder / "by_mcap_ros2.mcap", "wb") as f:
        writer = McapRos2Writer(f, compression=CompressionType.ZSTD)
        schemas = {}
        for ns, topic, msg in messages(ts, rate):
            name = msg.__msgtype__
            if name not in schemas:
                schemas[name] = writer.register_msgdef(name, ts.generate_msgdef(name, ros_version=2)[0])
            writer.write_message(topic, schemas[name], as_dict(msg), log_time=ns, publish_time=ns)
        writer.finish()


def as_dict(value):
    """A rosbags message as the nested dicts mcap-ros2-support writes."""
    if isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, list):
        return [as_dict(v) for v in value]
    return {
        f: as_dict(getattr(value, f))
        for f in value.__dataclass_fields__
        if not f.startswith("__") and not f.isupper()
    }


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "write":
        write(sys.argv[2], float(sys.argv[3]))
    else:
        sys.exit(__doc__)
