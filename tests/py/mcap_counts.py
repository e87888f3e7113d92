#!/usr/bin/env python3
"""Counts the messages of MCAP files with the `mcap` package, and reads a rosbag2 folder with
`rosbags` (both independent of xsurf), as JSON.

usage: mcap_counts.py FILE.mcap...      -> {"files": [{"count", "first", "last"}], "topics": {name: {"count", "type", "encoding"}}}
       mcap_counts.py --rosbags DIR     -> {"topics": {name: count}, "messages": n}
"""
import json
import sys

from mcap.reader import make_reader


def mcap_files(paths):
    topics = {}
    files = []
    for p in paths:
        with open(p, "rb") as f:
            first, last, n = None, None, 0
            for schema, channel, message in make_reader(f).iter_messages():
                t = topics.setdefault(channel.topic, {"count": 0, "type": schema.name if schema else "",
                                                      "encoding": channel.message_encoding})
                t["count"] += 1
                n += 1
                first = message.log_time if first is None else min(first, message.log_time)
                last = message.log_time if last is None else max(last, message.log_time)
            files.append({"count": n, "first": first, "last": last})
    return {"files": files, "topics": topics}


def rosbags_dir(path):
    from pathlib import Path

    from rosbags.rosbag2 import Reader

    counts = {}
    with Reader(Path(path)) as r:
        for connection, _t, _raw in r.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
    return {"topics": counts, "messages": sum(counts.values())}


if __name__ == "__main__":
    if sys.argv[1] == "--rosbags":
        print(json.dumps(rosbags_dir(sys.argv[2])))
    else:
        print(json.dumps(mcap_files(sys.argv[1:])))
