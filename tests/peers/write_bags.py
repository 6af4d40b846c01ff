"""Writes the same sensor messages as ROS 1 bags (no, bz2 and lz4 chunk compression) and ROS 2
bags (MCAP and SQLite storage) with the `rosbags` package (the peer: its own serialisers and
message definitions), and `expected.json`: every message's topic, record time, header stamp and
the values a reader must decode. Used by ros/tests/rosbags.rs.

    python write_bags.py OUT_DIR
"""

import json
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

OUT = Path(sys.argv[1])
OUT.mkdir(parents=True, exist_ok=True)
W, H = 5, 3


def typestore(which):
    """rosbags' store for a distribution, with tf2_msgs (not among its defaults) added."""
    store = get_typestore(which)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return store


def stamp_of(store, ns):
    return store.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def header(store, ns, frame, seq):
    h = store.types["std_msgs/msg/Header"]
    t = stamp_of(store, ns)
    if "seq" in h.__dataclass_fields__:
        return h(seq=seq, stamp=t, frame_id=frame)
    return h(stamp=t, frame_id=frame)


def messages(store):
    """(topic, msgtype, log_time_ns, message, expected) for three frames."""
    T = store.types
    out = []
    rng = np.random.default_rng(7)
    for i in range(3):
        log = 1_700_000_000_000_000_000 + i * 33_333_333
        ns = log - 5_000_000  # header stamps 5 ms before the record time
        rgb = rng.integers(0, 256, size=(H, W, 3), dtype=np.uint8)
        step = W * 3 + 2  # two bytes of row padding
        padded = np.zeros((H, step), dtype=np.uint8)
        padded[:, : W * 3] = rgb.reshape(H, W * 3)
        img = T["sensor_msgs/msg/Image"](
            header=header(store, ns, "cam", i), height=H, width=W, encoding="rgb8", is_bigendian=0, step=step,
            data=padded.reshape(-1))
        out.append(("/cam/color", "sensor_msgs/msg/Image", log, img, {"rgb": rgb.reshape(-1).tolist()}))
        bgr = T["sensor_msgs/msg/Image"](
            header=header(store, ns, "cam", i), height=H, width=W, encoding="bgr8", is_bigendian=0, step=W * 3,
            data=rgb[:, :, ::-1].reshape(-1).copy())
        out.append(("/cam/bgr", "sensor_msgs/msg/Image", log, bgr, {"rgb": rgb.reshape(-1).tolist()}))
        depth_mm = rng.integers(0, 5000, size=(H, W), dtype=np.uint16)
        d = T["sensor_msgs/msg/Image"](
            header=header(store, ns, "depth", i), height=H, width=W, encoding="16UC1", is_bigendian=0, step=W * 2,
            data=np.frombuffer(depth_mm.astype("<u2").tobytes(), dtype=np.uint8))
        out.append(("/cam/depth", "sensor_msgs/msg/Image", log, d, {"depth_mm": depth_mm.reshape(-1).tolist()}))
        k = [520.0 + i, 0.0, 320.5, 0.0, 521.0, 240.5, 0.0, 0.0, 1.0]
        dist = [0.1, -0.05, 0.001, 0.002, 0.0]
        kw = dict(header=header(store, ns, "cam", i), height=480, width=640, distortion_model="plumb_bob",
                  binning_x=0, binning_y=0,
                  roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        if "K" in T["sensor_msgs/msg/CameraInfo"].__dataclass_fields__:
            kw.update(D=np.array(dist), K=np.array(k), R=np.eye(3).reshape(-1), P=np.zeros(12))
        else:
            kw.update(d=np.array(dist), k=np.array(k), r=np.eye(3).reshape(-1), p=np.zeros(12))
        info = T["sensor_msgs/msg/CameraInfo"](**kw)
        out.append(("/cam/info", "sensor_msgs/msg/CameraInfo", log, info, {"k": k, "d": dist}))
        for j in range(6):  # 200 Hz IMU samples between frames
            ins = ns + j * 5_000_000
            g, a = [0.01 * j, -0.02, 0.03 * i], [0.1, 9.81, -0.2 * j]
            V = T["geometry_msgs/msg/Vector3"]
            imu = T["sensor_msgs/msg/Imu"](
                header=header(store, ins, "imu", i), orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9), angular_velocity=V(x=g[0], y=g[1], z=g[2]),
                angular_velocity_covariance=np.zeros(9), linear_acceleration=V(x=a[0], y=a[1], z=a[2]),
                linear_acceleration_covariance=np.zeros(9))
            out.append(("/imu", "sensor_msgs/msg/Imu", log + j * 5_000_000, imu, {"gyro": g, "accel": a, "stamp_ns": ins}))
        q = [0.0, 0.0, np.sin(0.1 * i), np.cos(0.1 * i)]  # x y z w
        p = [1.0 + i, -2.0, 0.5 * i]
        V, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
        tr = T["geometry_msgs/msg/TransformStamped"](
            header=header(store, ns, "world", i), child_frame_id="cam",
            transform=T["geometry_msgs/msg/Transform"](translation=V(x=p[0], y=p[1], z=p[2]), rotation=Q(x=q[0], y=q[1], z=q[2], w=q[3])))
        out.append(("/tf", "tf2_msgs/msg/TFMessage", log, T["tf2_msgs/msg/TFMessage"](transforms=[tr]), {"t": p, "q": q, "child": "cam"}))
        P, Pt = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/Point"]
        pose = P(position=Pt(x=p[0], y=p[1], z=p[2]), orientation=Q(x=q[0], y=q[1], z=q[2], w=q[3]))
        ps = T["geometry_msgs/msg/PoseStamped"](header=header(store, ns, "world", i), pose=pose)
        out.append(("/pose", "geometry_msgs/msg/PoseStamped", log, ps, {"t": p, "q": q}))
        tw = T["geometry_msgs/msg/Twist"](linear=V(x=0.0, y=0.0, z=0.0), angular=V(x=0.0, y=0.0, z=0.0))
        od = T["nav_msgs/msg/Odometry"](
            header=header(store, ns, "odom", i), child_frame_id="base",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)))
        out.append(("/odom", "nav_msgs/msg/Odometry", log, od, {"t": p, "q": q, "child": "base"}))
    return out, ns


def expected_of(msgs):
    rows = []
    for topic, msgtype, log, msg, exp in msgs:
        stamp = msg.header.stamp if hasattr(msg, "header") else msg.transforms[0].header.stamp
        row = {"topic": topic, "type": msgtype, "log_time": log, "stamp_ns": stamp.sec * 10**9 + stamp.nanosec}
        row.update(exp)
        rows.append(row)
    return rows


def write_all(writer, store, msgs, serialize):
    """Each message on its topic's connection (added on first use), at its record time."""
    conns = {}
    for topic, msgtype, log, msg, _ in msgs:
        if topic not in conns:
            conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
        writer.write(conns[topic], log, serialize(msg, msgtype))


def write_ros1(path, fmt):
    store = typestore(Stores.ROS1_NOETIC)
    msgs, _ = messages(store)
    w = Writer1(path)
    if fmt != "none":
        w.set_compression({"bz2": Writer1.CompressionFormat.BZ2, "lz4": Writer1.CompressionFormat.LZ4}[fmt])
    with w:
        write_all(w, store, msgs, store.serialize_ros1)
    return expected_of(msgs)


def write_ros2(path, plugin):
    store = typestore(Stores.ROS2_HUMBLE)
    msgs, _ = messages(store)
    with Writer2(path, version=9, storage_plugin=plugin) as w:
        write_all(w, store, msgs, store.serialize_cdr)
    return expected_of(msgs)


expected = {}
for fmt in ["none", "bz2", "lz4"]:
    name = f"ros1_{fmt}.bag"
    (OUT / name).unlink(missing_ok=True)
    expected[name] = write_ros1(OUT / name, fmt)
for name, plugin in [("ros2_mcap", StoragePlugin.MCAP), ("ros2_sqlite", StoragePlugin.SQLITE3)]:
    d = OUT / name
    if d.exists():
        for f in d.iterdir():
            f.unlink()
        d.rmdir()
    expected[name] = write_ros2(d, plugin)
(OUT / "expected.json").write_text(json.dumps(expected))
print("wrote", ", ".join(expected))
