#!/usr/bin/env python3
"""Recordings checked by peers no one here wrote (pip: mcap, mcap-ros2-support, rosbags).

    peers.py decode RECORDING OUT.json [TOPIC...]
                                         both peers decode a recording the project wrote (every
                                         message, or only TOPICs'; all are counted per topic)
    peers.py write DIR                   both peers write recordings the project must read, and the
                                         values they wrote (DIR/expected.json)

Messages become JSON with their ROS field names: [topic, log_time_ns, type, {field: value}].
"""

import dataclasses
import json
import pathlib
import sys

from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as McapRos2Writer
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer as Rosbag2Writer
from rosbags.typesys import Stores, get_typestore


def is_field(name):
    """Not a constant (ROS 2 constants are upper case, fields lower case) nor the type's name."""
    return not name.startswith("__") and not name.isupper()


def plain(value):
    """A decoded message (mcap-ros2-support SimpleNamespace, rosbags dataclass) as plain JSON values."""
    if hasattr(value, "tolist"):  # numpy arrays and scalars (rosbags)
        return value.tolist()
    if isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value) if is_field(f.name)}
    if hasattr(value, "__slots__"):
        return {f: plain(getattr(value, f)) for f in value.__slots__ if is_field(f)}
    raise TypeError(f"cannot turn {type(value)} into JSON")


def mcap_files(path):
    path = pathlib.Path(path)
    return sorted(path.glob("*.mcap")) if path.is_dir() else [path]


def decode(recording, out, topics):
    counts = {"mcap_ros2": {}, "rosbags": {}}
    with_mcap = []
    for file in mcap_files(recording):
        with open(file, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for schema, channel, message, decoded in reader.iter_decoded_messages():
                counts["mcap_ros2"][channel.topic] = counts["mcap_ros2"].get(channel.topic, 0) + 1
                if not topics or channel.topic in topics:
                    with_mcap.append([channel.topic, message.log_time, schema.name, plain(decoded)])
    with_rosbags = []
    with AnyReader([pathlib.Path(recording)]) as reader:
        for connection, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            counts["rosbags"][connection.topic] = counts["rosbags"].get(connection.topic, 0) + 1
            if not topics or connection.topic in topics:
                with_rosbags.append([connection.topic, timestamp, connection.msgtype, plain(msg)])
    result = {"mcap_ros2": with_mcap, "rosbags": with_rosbags, "counts": counts}
    pathlib.Path(out).write_text(json.dumps(result))


def samples(ts, i):
    """The i-th set of messages both writers write, as rosbags objects."""
    Time = ts.types["builtin_interfaces/msg/Time"]
    Header = ts.types["std_msgs/msg/Header"]
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    Point = ts.types["geometry_msgs/msg/Point"]
    Quaternion = ts.types["geometry_msgs/msg/Quaternion"]
    header = Header(stamp=Time(sec=1_700_000_000 + i, nanosec=1000 * i + 7), frame_id="ft_sensor")
    wrench = ts.types["geometry_msgs/msg/WrenchStamped"](
        header=header,
        wrench=ts.types["geometry_msgs/msg/Wrench"](
            force=Vector3(x=0.1 * i, y=-2.5, z=-140.0 - i / 3), torque=Vector3(x=1e-3, y=-i * 1e-4, z=0.25)
        ),
    )
    world = Header(stamp=header.stamp, frame_id="world")
    pose = ts.types["geometry_msgs/msg/PoseStamped"](
        header=world,
        pose=ts.types["geometry_msgs/msg/Pose"](
            position=Point(x=0.5, y=0.0, z=0.3 - i * 1e-4), orientation=Quaternion(x=1.0, y=0.0, z=0.0, w=0.0)
        ),
    )
    twist = ts.types["geometry_msgs/msg/TwistStamped"](
        header=world,
        twist=ts.types["geometry_msgs/msg/Twist"](
            linear=Vector3(x=0.0, y=0.0, z=-0.01 * i), angular=Vector3(x=0.0, y=1e-3, z=0.0)
        ),
    )
    import numpy as np

    joints = ts.types["sensor_msgs/msg/JointState"](
        header=Header(stamp=header.stamp, frame_id=""),
        name=[f"lwr_joint_{j + 1}" for j in range(7)],
        position=np.array([0.1 * j + i * 1e-3 for j in range(7)], dtype=np.float64),
        velocity=np.array([-0.01 * j for j in range(7)], dtype=np.float64),
        effort=np.array([], dtype=np.float64),
    )
    tf = ts.types["tf2_msgs/msg/TFMessage"](
        transforms=[
            ts.types["geometry_msgs/msg/TransformStamped"](
                header=Header(stamp=header.stamp, frame_id="lwr_tool"),
                child_frame_id="ft_sensor",
                transform=ts.types["geometry_msgs/msg/Transform"](
                    translation=Vector3(x=0.0, y=0.0, z=0.1), rotation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
                ),
            )
        ]
    )
    return [
        ("/ft_sensor/wrench", wrench),
        ("/lwr/ee_pose", pose),
        ("/lwr/ee_twist", twist),
        ("/lwr/joint_states", joints),
        ("/tf_static", tf),
    ]


def write(folder):
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ts = get_typestore(Stores.ROS2_JAZZY)
    expected = []
    # rosbags: a rosbag2 folder with MCAP storage.
    with Rosbag2Writer(folder / "by_rosbags", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for i in range(20):
            for topic, msg in samples(ts, i):
                if topic not in connections:
                    connections[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=ts)
                t = 1_700_000_000_000_000_000 + i * 1_000_000
                writer.write(connections[topic], t, ts.serialize_cdr(msg, msg.__msgtype__))
                expected.append(["by_rosbags", topic, t, msg.__msgtype__, plain(msg)])
    # mcap-ros2-support: one .mcap file of small lz4 chunks, messages given as dicts, definitions rosbags
    # generates.
    with open(folder / "by_mcap_ros2.mcap", "wb") as f:
        writer = McapRos2Writer(f, chunk_size=4096, compression=CompressionType.LZ4)
        schemas = {}
        for i in range(20):
            for topic, msg in samples(ts, i):
                name = msg.__msgtype__
                if name not in schemas:
                    schemas[name] = writer.register_msgdef(name, ts.generate_msgdef(name, ros_version=2)[0])
                t = 1_700_000_000_000_000_000 + i * 1_000_000
                writer.write_message(topic, schemas[name], plain(msg), log_time=t, publish_time=t)
                expected.append(["by_mcap_ros2", topic, t, name, plain(msg)])
        writer.finish()
    (folder / "expected.json").write_text(json.dumps(expected))


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "decode":
        decode(sys.argv[2], sys.argv[3], set(sys.argv[4:]))
    elif len(sys.argv) == 3 and sys.argv[1] == "write":
        write(sys.argv[2])
    else:
        sys.exit(__doc__)
