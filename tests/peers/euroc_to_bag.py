"""Writes a EuRoC MAV folder (as `dynaflow synth --format euroc` writes one, with `depth0/`) as
a ROS 2 bag (MCAP storage) with the `rosbags` package (the peer), the way a robot records the
same rig: cam0 as `Image`, depth0 as `16UC1` holding the PNG's values, cam0's `CameraInfo`,
imu0 as `sensor_msgs/Imu` in frame `imu`, the camera's mounting (cam0's `T_BS`) on
/tf_static as `imu -> cam0`, and the ground truth (the body's pose) on /tf as
`world -> imu`. Every stamp is the folder's nanoseconds. Used by tests/bags.rs.

    python euroc_to_bag.py MAV0_DIR OUT_BAG_DIR
"""

import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

MAV0, OUT = Path(sys.argv[1]), Path(sys.argv[2])
store = get_typestore(Stores.ROS2_HUMBLE)
store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
T = store.types


def csv(path):
    return [l.split(",") for l in path.read_text().splitlines() if l.strip() and not l.startswith("#")]


def yaml_numbers(path, key):
    text = path.read_text()
    start = text.index("[", text.index(key))
    return [float(v) for v in text[start + 1 : text.index("]", start)].replace("\n", " ").split(",")]


def quat_of(r):
    """x, y, z, w of a rotation matrix (Shepperd's method)."""
    t = np.trace(r)
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        return [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
    q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
    q[i] = 0.25 * s
    q[j] = (r[j, i] + r[i, j]) / s
    q[k] = (r[k, i] + r[i, k]) / s
    return q


def header(ns, frame):
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)


def transform(ns, parent, child, t, q):
    V, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    tr = T["geometry_msgs/msg/Transform"](translation=V(x=t[0], y=t[1], z=t[2]), rotation=Q(x=q[0], y=q[1], z=q[2], w=q[3]))
    return T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](header=header(ns, parent), child_frame_id=child, transform=tr)])


def image(ns, frame, array, encoding):
    channels = array.shape[2] if array.ndim == 3 else 1
    step = array.shape[1] * array.itemsize * channels
    return T["sensor_msgs/msg/Image"](header=header(ns, frame), height=array.shape[0], width=array.shape[1], encoding=encoding,
                                      is_bigendian=0, step=step, data=np.frombuffer(array.astype(array.dtype.newbyteorder("<")).tobytes(), dtype=np.uint8))


rows = []  # (ns, topic, type, message)
t_bs = np.array(yaml_numbers(MAV0 / "cam0/sensor.yaml", "data:")).reshape(4, 4)
fu, fv, cu, cv = yaml_numbers(MAV0 / "cam0/sensor.yaml", "intrinsics:")
w, h = [int(v) for v in yaml_numbers(MAV0 / "cam0/sensor.yaml", "resolution:")]
cam = csv(MAV0 / "cam0/data.csv")
first = int(cam[0][0])
rows.append((first, "/tf_static", "tf2_msgs/msg/TFMessage", transform(first, "imu", "cam0", t_bs[:3, 3].tolist(), quat_of(t_bs[:3, :3]))))
for ns, name in cam:
    ns = int(ns)
    img = cv2.imread(str(MAV0 / "cam0/data" / name.strip()), cv2.IMREAD_UNCHANGED)
    if img.ndim == 3:
        rows.append((ns, "/cam0/image_raw", "sensor_msgs/msg/Image", image(ns, "cam0", img[:, :, ::-1].copy(), "rgb8")))
    else:
        rows.append((ns, "/cam0/image_raw", "sensor_msgs/msg/Image", image(ns, "cam0", img, "mono8")))
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    info = T["sensor_msgs/msg/CameraInfo"](header=header(ns, "cam0"), height=h, width=w, distortion_model="plumb_bob",
                                            d=np.zeros(5), k=np.array([fu, 0, cu, 0, fv, cv, 0, 0, 1.0]), r=np.eye(3).reshape(-1),
                                            p=np.array([fu, 0, cu, 0, 0, fv, cv, 0, 0, 0, 1.0, 0]), binning_x=0, binning_y=0, roi=roi)
    rows.append((ns, "/cam0/camera_info", "sensor_msgs/msg/CameraInfo", info))
for ns, name in csv(MAV0 / "depth0/data.csv"):
    ns = int(ns)
    d = cv2.imread(str(MAV0 / "depth0/data" / name.strip()), cv2.IMREAD_UNCHANGED)
    rows.append((ns, "/depth0/image_raw", "sensor_msgs/msg/Image", image(ns, "cam0", d, "16UC1")))
V = T["geometry_msgs/msg/Vector3"]
for r in csv(MAV0 / "imu0/data.csv"):
    ns, g, a = int(r[0]), [float(v) for v in r[1:4]], [float(v) for v in r[4:7]]
    imu = T["sensor_msgs/msg/Imu"](header=header(ns, "imu"), orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                                   orientation_covariance=np.array([-1.0] + [0.0] * 8), angular_velocity=V(x=g[0], y=g[1], z=g[2]),
                                   angular_velocity_covariance=np.zeros(9), linear_acceleration=V(x=a[0], y=a[1], z=a[2]),
                                   linear_acceleration_covariance=np.zeros(9))
    rows.append((ns, "/imu0", "sensor_msgs/msg/Imu", imu))
for r in csv(MAV0 / "state_groundtruth_estimate0/data.csv"):
    ns, p, q = int(r[0]), [float(v) for v in r[1:4]], [float(v) for v in r[4:8]]  # q: w x y z
    rows.append((ns, "/tf", "tf2_msgs/msg/TFMessage", transform(ns, "world", "imu", p, [q[1], q[2], q[3], q[0]])))
rows.sort(key=lambda r: r[0])
if OUT.exists():
    shutil.rmtree(OUT)
conns = {}
with Writer(OUT, version=9, storage_plugin=StoragePlugin.MCAP) as wr:
    for ns, topic, ty, msg in rows:
        if topic not in conns:
            conns[topic] = wr.add_connection(topic, ty, typestore=store)
        wr.write(conns[topic], ns, store.serialize_cdr(msg, ty))
print("wrote", OUT)
