#!/usr/bin/env python3
"""Read a dynaflow MCAP end to end with the reference Python `mcap` reader, CRCs validated.

Checks: every channel has a schema; images, annotations, poses and point clouds use Foxglove
schema names; every message is JSON with a `dynaflow` object. Prints `messages N`.
With --truncated the file comes from a killed run: it is read in streaming mode up to the last
complete record, and every message read must still be valid.
"""
import json
import sys

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.records import Message, Channel, Schema
from mcap.exceptions import McapError

FOXGLOVE = {
    "image": "foxglove.CompressedImage", "depth": "foxglove.CompressedImage", "mask": "foxglove.CompressedImage",
    "keypoints": "foxglove.ImageAnnotations", "tracks": "foxglove.ImageAnnotations", "detections": "foxglove.ImageAnnotations",
    "pose": "foxglove.PoseInFrame", "trajectory": "foxglove.PosesInFrame", "point_cloud": "foxglove.PointCloud",
    "camera_info": "foxglove.CameraCalibration", "octree_update": "foxglove.SceneUpdate",
}


def check_message(channel, schema, data):
    assert schema is not None and schema.name, f"channel {channel.topic} has no schema"
    assert schema.encoding == "jsonschema", schema.encoding
    json.loads(schema.data)
    ty = channel.metadata.get("dynaflow.type")
    if ty in FOXGLOVE:
        assert schema.name == FOXGLOVE[ty], f"{channel.topic}: {schema.name} != {FOXGLOVE[ty]}"
    msg = json.loads(data)
    assert "dynaflow" in msg and len(msg["dynaflow"]["digest"]) == 16, channel.topic


def main():
    truncated = "--truncated" in sys.argv
    path = [a for a in sys.argv[1:] if not a.startswith("--")][0]
    count = 0
    with open(path, "rb") as f:
        if not truncated:
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            assert summary is not None, "no summary section"
            for schema, channel, message in reader.iter_messages():
                check_message(channel, schema, message.data)
                count += 1
            assert count == summary.statistics.message_count, (count, summary.statistics.message_count)
            meta = [m for m in reader.iter_metadata() if m.name == "dynaflow"]
            assert meta and "graph_yaml" in meta[0].metadata, "no provenance metadata"
        else:
            schemas, channels = {}, {}
            try:
                for record in StreamReader(f, skip_magic=False, validate_crcs=True).records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        channels[record.id] = record
                    elif isinstance(record, Message):
                        ch = channels[record.channel_id]
                        check_message(ch, schemas.get(ch.schema_id), record.data)
                        count += 1
            except (McapError, EOFError, ValueError) as e:  # the cut: expected for a killed run
                print(f"stopped at the cut: {type(e).__name__}: {e}")
            assert count > 0, "no message before the cut"
    print(f"messages {count}")


if __name__ == "__main__":
    main()
