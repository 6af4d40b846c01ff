"""Reads a rosbag2 bag with the `rosbags` package (the peer) and prints, as JSON, per topic its
type, how many messages it holds, and a few decoded values a reader would show: the header
frame of each message type, image sizes and encodings, the last pose, the tf edges. Every
message is deserialised with the definition the bag stores; one that fails fails the script.
Used by tests/bags.rs.

    python read_ros2_bag.py BAG_DIR
"""

import json
import sys
from pathlib import Path

from rosbags.highlevel import AnyReader

out = {}
with AnyReader([Path(sys.argv[1])]) as reader:
    for conn, _, raw in reader.messages():
        msg = reader.deserialize(raw, conn.msgtype)
        t = out.setdefault(conn.topic, {"type": conn.msgtype, "count": 0})
        t["count"] += 1
        header = getattr(msg, "header", None)
        if header is not None:
            t["frame_id"] = header.frame_id
            t["last_stamp"] = [header.stamp.sec, header.stamp.nanosec]
        if conn.msgtype == "sensor_msgs/msg/Image":
            t["size"] = [msg.width, msg.height]
            t["encoding"] = msg.encoding
            assert len(msg.data) == msg.step * msg.height, conn.topic
        elif conn.msgtype == "sensor_msgs/msg/CompressedImage":
            t["format"] = msg.format
        elif conn.msgtype == "geometry_msgs/msg/PoseStamped":
            p, q = msg.pose.position, msg.pose.orientation
            t["last_pose"] = [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
        elif conn.msgtype == "nav_msgs/msg/Path":
            t["poses"] = len(msg.poses)
        elif conn.msgtype == "tf2_msgs/msg/TFMessage":
            t["edges"] = sorted({f"{e.header.frame_id}->{e.child_frame_id}" for e in msg.transforms})
        elif conn.msgtype == "sensor_msgs/msg/PointCloud2":
            t["points"] = t.get("points", 0) + msg.width * msg.height
            t["fields"] = [f.name for f in msg.fields]
        elif conn.msgtype == "sensor_msgs/msg/CameraInfo":
            t["k"] = list(msg.k)
print(json.dumps(out))
