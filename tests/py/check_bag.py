#!/usr/bin/env python3
"""Reads a bag in full with two independent readers and prints what they saw as JSON.

- rosbags: Reader (raw) and AnyReader (deserialising every message with the bag's own
  definitions);
- mcap + mcap-ros2-support: every message decoded from the MCAP schemas.

Exits 1 if a reader fails or the counts disagree with metadata.yaml.
usage: check_bag.py BAG
"""
import json
import pathlib
import sys

from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main(bag):
    bag = pathlib.Path(bag)
    out = {"rosbags_counts": {}, "anyreader_counts": {}, "mcap_counts": {}, "metadata_counts": {}}
    with Reader(bag) as r:
        out["metadata_counts"] = {c.topic: c.msgcount for c in r.connections}
        out["metadata_total"] = r.message_count
        for conn, _t, _raw in r.messages():
            out["rosbags_counts"][conn.topic] = out["rosbags_counts"].get(conn.topic, 0) + 1
    samples = {}
    with AnyReader([bag]) as r:
        for conn, t, raw in r.messages():
            msg = r.deserialize(raw, conn.msgtype)
            out["anyreader_counts"][conn.topic] = out["anyreader_counts"].get(conn.topic, 0) + 1
            if conn.topic in samples:
                continue
            if conn.msgtype == "sensor_msgs/msg/Image":
                samples[conn.topic] = {"width": int(msg.width), "height": int(msg.height), "encoding": msg.encoding,
                                       "step": int(msg.step), "frame_id": msg.header.frame_id,
                                       "sum": int(msg.data.astype("uint64").sum())}
            elif conn.msgtype == "sensor_msgs/msg/CameraInfo":
                samples[conn.topic] = {"k": [float(v) for v in msg.k], "d": [float(v) for v in msg.d],
                                       "model": msg.distortion_model}
            elif conn.msgtype == "tf2_msgs/msg/TFMessage":
                tr = msg.transforms[0]
                samples[conn.topic] = {"parent": tr.header.frame_id, "child": tr.child_frame_id,
                                       "stamp": tr.header.stamp.sec * 10**9 + tr.header.stamp.nanosec,
                                       "t": [tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z],
                                       "q": [tr.transform.rotation.x, tr.transform.rotation.y, tr.transform.rotation.z, tr.transform.rotation.w]}
            elif conn.msgtype == "xsurf_msgs/msg/ScanEvent":
                samples[conn.topic] = {"scan_id": int(msg.scan_id), "event": int(msg.event)}
            elif conn.msgtype == "sensor_msgs/msg/JointState":
                samples[conn.topic] = {"name": list(msg.name), "position": [float(p) for p in msg.position]}
    out["samples"] = samples
    for f in sorted(bag.glob("*.mcap")):
        with open(f, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _schema, channel, _message, _decoded in reader.iter_decoded_messages():
                out["mcap_counts"][channel.topic] = out["mcap_counts"].get(channel.topic, 0) + 1
    ok = out["rosbags_counts"] == out["anyreader_counts"] == out["mcap_counts"] == out["metadata_counts"]
    ok = ok and sum(out["metadata_counts"].values()) == out["metadata_total"]
    out["agree"] = ok
    print(json.dumps(out))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
