#!/usr/bin/env python3
"""Rewrites a bag with the `rosbags` Writer (metadata version 9, MCAP storage, the Jazzy layout),
so the test suite can check that xsurf reads bags it did not write.
usage: rosbags_write.py SRC_BAG DST_BAG
"""
import pathlib
import sys

from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer


def main(src, dst):
    with AnyReader([pathlib.Path(src)]) as r:
        with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            conns = {}
            for c in r.connections:
                # The bag's own definitions carry our xsurf_msgs types too.
                conns[c.topic] = w.add_connection(c.topic, c.msgtype, typestore=r.typestore)
            for c, t, raw in r.messages():
                w.write(conns[c.topic], t, raw)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
