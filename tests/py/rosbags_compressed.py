#!/usr/bin/env python3
"""Rewrites a bag with the `rosbags` Writer, every `/<cam>/image_raw` (mono8 or rgb8) turned into
`sensor_msgs/msg/CompressedImage` on `/<cam>/image_raw/compressed`, the bytes made by Pillow
(JPEG quality 85 for cam1, PNG for the others) with image_transport's format strings. Pillow's
own decoding of the first frames of each camera is written beside, as the pixels xsurf must
decode to (`DST/pillow/<cam>_<k>.bin`, raw rows, and `DST/pillow/index.json`).
usage: rosbags_compressed.py SRC_BAG DST_BAG
"""
import io
import json
import pathlib
import sys

import numpy as np
from PIL import Image
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

KEEP = 3


def main(src, dst):
    store = get_typestore(Stores.ROS2_HUMBLE)
    CompressedImage = store.types["sensor_msgs/msg/CompressedImage"]
    dst = pathlib.Path(dst)
    index, kept = [], {}
    with AnyReader([pathlib.Path(src)]) as r:
        with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            conns = {}
            for c in r.connections:
                if c.topic.endswith("/image_raw"):
                    conns[c.topic] = w.add_connection(c.topic + "/compressed", CompressedImage.__msgtype__, typestore=store)
                else:
                    conns[c.topic] = w.add_connection(c.topic, c.msgtype, typestore=r.typestore)
            for c, t, raw in r.messages():
                if not c.topic.endswith("/image_raw"):
                    w.write(conns[c.topic], t, raw)
                    continue
                m = r.deserialize(raw, c.msgtype)
                cam = c.topic.strip("/").split("/")[0]
                mode = {"mono8": "L", "rgb8": "RGB"}[m.encoding]
                shape = (m.height, m.width) if mode == "L" else (m.height, m.width, 3)
                pixels = np.asarray(m.data, dtype=np.uint8).reshape(m.height, m.step)[:, : m.width * len(mode)]
                img = Image.fromarray(pixels.reshape(shape), mode)
                buf = io.BytesIO()
                if cam == "cam1":
                    img.save(buf, format="JPEG", quality=85)
                    fmt = f"{m.encoding}; jpeg compressed " + ("bgr8" if mode == "RGB" else "")
                else:
                    img.save(buf, format="PNG")
                    fmt = f"{m.encoding}; png compressed " + ("bgr8" if mode == "RGB" else "")
                data = buf.getvalue()
                out = CompressedImage(header=m.header, format=fmt, data=np.frombuffer(data, dtype=np.uint8))
                w.write(conns[c.topic], t, store.serialize_cdr(out, CompressedImage.__msgtype__))
                k = kept.get(cam, 0)
                if k < KEEP:
                    kept[cam] = k + 1
                    decoded = np.asarray(Image.open(io.BytesIO(data)))
                    (dst / "pillow").mkdir(exist_ok=True)
                    name = f"{cam}_{k}.bin"
                    (dst / "pillow" / name).write_bytes(decoded.tobytes())
                    stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
                    index.append({"camera": cam, "stamp_ns": stamp, "file": name, "format": fmt,
                                  "width": m.width, "height": m.height})
    (dst / "pillow" / "index.json").write_text(json.dumps(index))
    print(json.dumps({"frames": index}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
