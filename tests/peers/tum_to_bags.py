"""Writes one TUM RGB-D folder (as `dynaflow synth` writes it) as ROS bags with the `rosbags`
package (the peer: its own serialisers and message definitions). Used by tests/bags.rs.

    python tum_to_bags.py TUM_DIR OUT_DIR

Each frame's header stamp is its TUM stamp, split into sec/nanosec from the decimal text (so a
reader's seconds equal the TUM reader's); the record time lags it (a driver's latency), so a
reader that paired by record time would pair wrongly.

  raw.bag, raw_mcap/, raw_sqlite/   ROS 1 (lz4 chunks), ROS 2 MCAP, ROS 2 SQLite: colour as
                                    `rgb8` Image, depth as `16UC1` Image holding the PNG's
                                    values (TUM's 5000 per metre), CameraInfo from
                                    calibration.txt, ground truth as PoseStamped.
  jpeg_mcap/                        the same with colour as a JPEG CompressedImage (quality 95).
  robot.bag                         a robot's recording: RealSense-style topic names, JPEG
                                    colour, depth in millimetres (REP 118), a second colour
                                    camera, an IMU, wheel odometry, ground truth only in /tf
                                    (odom -> base_link moving, base_link -> the optical frame in
                                    /tf_static), record times 30-60 ms late and
                                    out of header order across topics, and every tenth colour
                                    frame missing (its depth then has no partner).
  bad_*.bag                         one defect each, 5 frames: two_colour (two colour topics),
                                    encoding (colour as `yuv422`), no_info (no CameraInfo),
                                    never_pair (depth stamped 0.5 s late).
"""

import math
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

TUM, OUT = Path(sys.argv[1]), Path(sys.argv[2])
OUT.mkdir(parents=True, exist_ok=True)


def typestore(which):
    """rosbags' store for a distribution, with tf2_msgs (not among its defaults) added."""
    store = get_typestore(which)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return store


def ns_of(text):
    """Nanoseconds of a decimal stamp, exactly as written."""
    whole, _, frac = text.partition(".")
    return int(whole) * 10**9 + int((frac + "000000000")[:9])


def listing(name):
    rows = []
    for line in (TUM / name).read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            rows.append(line.split())
    return rows


RGB = [(ns_of(r[0]), TUM / r[1]) for r in listing("rgb.txt")]
DEPTH = [(ns_of(r[0]), TUM / r[1]) for r in listing("depth.txt")]
GT = [(ns_of(r[0]), [float(v) for v in r[1:8]]) for r in listing("groundtruth.txt")]
calib = next(line for line in (TUM / "calibration.txt").read_text().splitlines() if line.strip() and not line.startswith("#"))
CALIB = [float(v) for v in calib.replace(",", " ").split()]
K = [CALIB[0], 0.0, CALIB[2], 0.0, CALIB[1], CALIB[3], 0.0, 0.0, 1.0]
D = (CALIB[4:] + [0.0] * 5)[:5]
H, W = cv2.imread(str(RGB[0][1]), cv2.IMREAD_UNCHANGED).shape[:2]


class Bag:
    """Messages gathered for one bag, written in record-time order."""

    def __init__(self, distro):
        self.store = typestore(distro)
        self.T = self.store.types
        self.rows = []

    def header(self, ns, frame):
        h, t = self.T["std_msgs/msg/Header"], self.T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        return h(seq=0, stamp=t, frame_id=frame) if "seq" in h.__dataclass_fields__ else h(stamp=t, frame_id=frame)

    def add(self, topic, msgtype, log_ns, msg):
        self.rows.append((log_ns, len(self.rows), topic, msgtype, msg))

    def image(self, topic, ns, log, frame, array, encoding):
        step = array.shape[1] * array.itemsize * (array.shape[2] if array.ndim == 3 else 1)
        data = np.frombuffer(np.ascontiguousarray(array).astype(array.dtype.newbyteorder("<")).tobytes(), dtype=np.uint8)
        msg = self.T["sensor_msgs/msg/Image"](header=self.header(ns, frame), height=array.shape[0], width=array.shape[1],
                                               encoding=encoding, is_bigendian=0, step=step, data=data)
        self.add(topic, "sensor_msgs/msg/Image", log, msg)

    def jpeg(self, topic, ns, log, frame, rgb):
        ok, buf = cv2.imencode(".jpg", rgb[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 95])
        assert ok
        msg = self.T["sensor_msgs/msg/CompressedImage"](header=self.header(ns, frame), format="rgb8; jpeg compressed bgr8",
                                                         data=np.frombuffer(buf.tobytes(), dtype=np.uint8))
        self.add(topic, "sensor_msgs/msg/CompressedImage", log, msg)

    def camera_info(self, topic, ns, log, frame):
        T = self.T
        kw = dict(header=self.header(ns, frame), height=H, width=W, distortion_model="plumb_bob", binning_x=0, binning_y=0,
                  roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        p = [K[0], 0.0, K[2], 0.0, 0.0, K[4], K[5], 0.0, 0.0, 0.0, 1.0, 0.0]
        if "K" in T["sensor_msgs/msg/CameraInfo"].__dataclass_fields__:
            kw.update(D=np.array(D), K=np.array(K), R=np.eye(3).reshape(-1), P=np.array(p))
        else:
            kw.update(d=np.array(D), k=np.array(K), r=np.eye(3).reshape(-1), p=np.array(p))
        self.add(topic, "sensor_msgs/msg/CameraInfo", log, T["sensor_msgs/msg/CameraInfo"](**kw))

    def pose(self, t, q):
        T = self.T
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=t[0], y=t[1], z=t[2]),
                                           orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))

    def transform(self, ns, parent, child, t, q):
        T = self.T
        V, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
        return T["geometry_msgs/msg/TransformStamped"](
            header=self.header(ns, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=V(x=t[0], y=t[1], z=t[2]),
                                                       rotation=Q(x=q[0], y=q[1], z=q[2], w=q[3])))

    def write(self, path, kind):
        if path.is_dir():
            shutil.rmtree(path)
        path.unlink(missing_ok=True)
        self.rows.sort(key=lambda r: (r[0], r[1]))
        if kind == "ros1":
            w = Writer1(path)
            w.set_compression(Writer1.CompressionFormat.LZ4)
            serialize = self.store.serialize_ros1
        else:
            w = Writer2(path, version=9, storage_plugin={"mcap": StoragePlugin.MCAP, "sqlite": StoragePlugin.SQLITE3}[kind])
            serialize = self.store.serialize_cdr
        conns = {}
        with w:
            for log, _, topic, msgtype, msg in self.rows:
                if topic not in conns:
                    kw = {"typestore": self.store}
                    if kind == "ros1" and topic == "/tf_static":
                        kw["callerid"] = "/static_transform_publisher"
                    conns[topic] = w.add_connection(topic, msgtype, **kw)
                w.write(conns[topic], log, serialize(msg, msgtype))


def rgb_of(path):
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return img[:, :, 2::-1] if img.ndim == 3 else img


def depth_of(path):
    d = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert d.dtype == np.uint16, path
    return d


LAG = 30_000_000  # record time after header stamp, ns


def tum_bag(distro, colour="raw", frames=None, encoding="rgb8", info=True, depth_shift=0, second_colour=False):
    """The TUM folder as a bag with TUM-like topics."""
    b = Bag(distro)
    for i, (ns, path) in enumerate(RGB[:frames]):
        rgb = rgb_of(path)
        if colour == "jpeg":
            b.jpeg("/camera/rgb/image_color/compressed", ns, ns + LAG, "rgb", rgb)
        else:
            b.image("/camera/rgb/image_color", ns, ns + LAG, "rgb", rgb, encoding)
        if second_colour:
            b.image("/camera/ir/image", ns, ns + LAG, "ir", rgb, "rgb8")
        if info:
            b.camera_info("/camera/rgb/camera_info", ns, ns + LAG, "rgb")
    for ns, path in DEPTH[:frames]:
        b.image("/camera/depth/image", ns + depth_shift, ns + LAG, "rgb", depth_of(path), "16UC1")
    for ns, v in GT:
        b.add("/groundtruth", "geometry_msgs/msg/PoseStamped", ns + LAG,
              b.T["geometry_msgs/msg/PoseStamped"](header=b.header(ns, "world"), pose=b.pose(v[0:3], v[3:7])))
    return b


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return [aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz]


def quat_rotate(q, v):
    qv = quat_mul(quat_mul(q, [v[0], v[1], v[2], 0.0]), [-q[0], -q[1], -q[2], q[3]])
    return qv[:3]


def robot_bag():
    """See the module documentation. base_link -> optical frame: REP 103's body axes (x forward,
    z up) to the optical frame's (z forward, x right), 10 cm forward and 20 cm up."""
    b = Bag(Stores.ROS1_NOETIC)
    epoch = 0  # the TUM stamps are seconds since 1970 already
    s = math.sqrt(0.5)
    q_bc = quat_mul([0.0, 0.0, -s, s], [-s, 0.0, 0.0, s])  # Rz(-90) * Rx(-90): optical in base
    t_bc = [0.1, 0.0, 0.2]
    b.add("/tf_static", "tf2_msgs/msg/TFMessage", epoch,
          b.T["tf2_msgs/msg/TFMessage"](transforms=[b.transform(epoch + RGB[0][0], "base_link", "camera_color_optical_frame", t_bc, q_bc)]))
    q_cb = [-q_bc[0], -q_bc[1], -q_bc[2], q_bc[3]]
    t_cb = [-v for v in quat_rotate(q_cb, t_bc)]
    lag = np.random.default_rng(3)
    for i, (ns, path) in enumerate(RGB):
        ns += epoch
        if i % 10 != 9:
            b.jpeg("/camera/color/image_raw/compressed", ns, ns + int(lag.integers(30, 60)) * 1_000_000, "camera_color_optical_frame", rgb_of(path))
        b.camera_info("/camera/color/camera_info", ns, ns + 31_000_000, "camera_color_optical_frame")
        if i % 3 == 0:  # a lower-rate second camera
            b.image("/rear_camera/image_raw", ns, ns + 35_000_000, "rear", rgb_of(path)[::2, ::2].copy(), "rgb8")
    for ns, path in DEPTH:
        ns += epoch
        mm = np.round(depth_of(path).astype(np.float64) / 5.0).astype(np.uint16)  # 5000/m -> 1000/m
        b.image("/camera/aligned_depth_to_color/image_raw", ns, ns + int(lag.integers(30, 60)) * 1_000_000, "camera_color_optical_frame", mm, "16UC1")
    for ns, v in GT:
        ns += epoch
        t_wc, q_wc = v[0:3], v[3:7]
        q_wb = quat_mul(q_wc, q_cb)
        t_wb = [a + c for a, c in zip(t_wc, quat_rotate(q_wc, t_cb))]
        b.add("/tf", "tf2_msgs/msg/TFMessage", ns + 2_000_000,
              b.T["tf2_msgs/msg/TFMessage"](transforms=[b.transform(ns, "odom", "base_link", t_wb, q_wb)]))
        T = b.T
        odom = T["nav_msgs/msg/Odometry"](
            header=b.header(ns, "odom"), child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=b.pose([t_wb[0] * 1.05, t_wb[1], 0.0], q_wb), covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                                   angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                covariance=np.zeros(36)))
        b.add("/wheel/odom", "nav_msgs/msg/Odometry", ns + 5_000_000, odom)
    for k in range(int((RGB[-1][0] - RGB[0][0]) / 5_000_000)):  # 200 Hz
        ns = epoch + RGB[0][0] + k * 5_000_000
        V = b.T["geometry_msgs/msg/Vector3"]
        imu = b.T["sensor_msgs/msg/Imu"](
            header=b.header(ns, "imu_link"), orientation=b.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9), angular_velocity=V(x=0.0, y=0.0, z=0.0),
            angular_velocity_covariance=np.zeros(9), linear_acceleration=V(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=np.zeros(9))
        b.add("/camera/imu", "sensor_msgs/msg/Imu", ns + 1_000_000, imu)
    return b


ROS1, ROS2 = Stores.ROS1_NOETIC, Stores.ROS2_HUMBLE
tum_bag(ROS1).write(OUT / "raw.bag", "ros1")
tum_bag(ROS2).write(OUT / "raw_mcap", "mcap")
tum_bag(ROS2).write(OUT / "raw_sqlite", "sqlite")
tum_bag(ROS2, colour="jpeg").write(OUT / "jpeg_mcap", "mcap")
robot_bag().write(OUT / "robot.bag", "ros1")
tum_bag(ROS1, frames=5, second_colour=True).write(OUT / "bad_two_colour.bag", "ros1")
tum_bag(ROS1, frames=5, encoding="yuv422").write(OUT / "bad_encoding.bag", "ros1")
tum_bag(ROS1, frames=5, info=False).write(OUT / "bad_no_info.bag", "ros1")
tum_bag(ROS1, frames=5, depth_shift=500_000_000).write(OUT / "bad_never_pair.bag", "ros1")
print("wrote", ", ".join(sorted(p.name for p in OUT.iterdir())))
