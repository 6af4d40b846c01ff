#!/usr/bin/env python3
"""Read a dynaflow MCAP end to end with the reference Python `mcap` reader, CRCs validated.

Checks: every channel has a schema; images, annotations, poses and point clouds use Foxglove
schema names; every message carries a `dynaflow` object. JSON channels parse as JSON; image,
depth and mask channels are protobuf and are decoded with `google.protobuf` from the schema's
own FileDescriptorSet (as Foxglove does): `foxglove.RawImage` must hold width*height samples
in `step`-byte rows (`32FC1` depth, `mono8`/`16UC1` masks, `rgb8`/`mono8` colour),
`foxglove.CompressedImage` a JPEG or PNG file. Prints `messages N` and one
`pixels <topic> <schema> <encoding or format> <width>x<height>` line per image channel.
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
    "image": ("foxglove.CompressedImage", "foxglove.RawImage"), "depth": "foxglove.RawImage", "mask": "foxglove.RawImage",
    "keypoints": "foxglove.ImageAnnotations", "tracks": "foxglove.ImageAnnotations", "detections": "foxglove.ImageAnnotations",
    "pose": "foxglove.PoseInFrame", "trajectory": "foxglove.PosesInFrame", "point_cloud": "foxglove.PointCloud",
    "camera_info": "foxglove.CameraCalibration", "octree_update": "foxglove.SceneUpdate",
}


CLASSES = {}
SEEN = {}
SAMPLE_BYTES = {"32FC1": 4, "16UC1": 2, "mono8": 1, "rgb8": 3}
# The undeclared field holding the `dynaflow` payload (recordings/src/mcap/proto.rs).
PAYLOAD_FIELD = 1000


def protobuf_class(schema):
    """The message class of a protobuf schema, built from its FileDescriptorSet."""
    if schema.id not in CLASSES:
        from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

        files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
        pool = descriptor_pool.DescriptorPool()
        for fd in files.file:
            pool.Add(fd)
        CLASSES[schema.id] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return CLASSES[schema.id]


def payload_of(data):
    """The `dynaflow` payload: the unknown length-delimited field PAYLOAD_FIELD, read by hand."""
    i = 0

    def varint():
        nonlocal i
        v, shift = 0, 0
        while True:
            b = data[i]
            i += 1
            v |= (b & 0x7F) << shift
            shift += 7
            if b < 0x80:
                return v

    while i < len(data):
        key = varint()
        field, wire = key >> 3, key & 7
        if wire == 0:
            varint()
        elif wire == 1:
            i += 8
        elif wire == 5:
            i += 4
        elif wire == 2:
            n = varint()
            if field == PAYLOAD_FIELD:
                return json.loads(data[i:i + n])
            i += n
        else:
            raise AssertionError(f"wire type {wire}")
    raise AssertionError("no dynaflow payload")


def check_message(channel, schema, data):
    assert schema is not None and schema.name, f"channel {channel.topic} has no schema"
    ty = channel.metadata.get("dynaflow.type")
    if ty in FOXGLOVE:
        names = FOXGLOVE[ty] if isinstance(FOXGLOVE[ty], tuple) else (FOXGLOVE[ty],)
        assert schema.name in names, f"{channel.topic}: {schema.name} not in {names}"
    if channel.message_encoding == "protobuf":
        assert schema.encoding == "protobuf", schema.encoding
        msg = protobuf_class(schema).FromString(data)
        if schema.name == "foxglove.RawImage":
            per = SAMPLE_BYTES[msg.encoding]
            assert msg.step >= msg.width * per and len(msg.data) == msg.step * msg.height, channel.topic
            kind = msg.encoding
        else:
            assert msg.format in ("jpeg", "png"), msg.format
            magic = b"\xff\xd8" if msg.format == "jpeg" else b"\x89PNG"
            assert msg.data[:len(magic)] == magic, channel.topic
            kind = msg.format
        payload = payload_of(data)
        size = f"{payload['data']['width']}x{payload['data']['height']}"
        if schema.name == "foxglove.RawImage":
            assert size == f"{msg.width}x{msg.height}", channel.topic
        SEEN[channel.topic] = f"pixels {channel.topic} {schema.name} {kind} {size}"
    else:
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema", schema.encoding
        json.loads(schema.data)
        payload = json.loads(data)["dynaflow"]
    assert len(payload["digest"]) == 16, channel.topic


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
    for line in sorted(SEEN.values()):
        print(line)
    print(f"messages {count}")


if __name__ == "__main__":
    main()
