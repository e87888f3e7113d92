#!/usr/bin/env python3
"""Counts the messages of MCAP files with the `mcap` package, and reads a rosbag2 folder with
`rosbags` (both independent of xsurf), as JSON.

usage: mcap_counts.py FILE.mcap...      -> {"files": [{"count", "first", "last"}], "topics": {name: {"count", "type", "encoding"}}}
       mcap_counts.py --damaged FILE.mcap...  the same, counting each file up to the first record
                                        the reader cannot read (a file cut short), with "damage": why
       mcap_counts.py --rosbags DIR     -> {"topics": {name: count}, "messages": n}
"""
import json
import sys

from mcap.reader import NonSeekingReader, make_reader


def mcap_files(paths, damaged=False):
    topics = {}
    files = []
    for p in paths:
        with open(p, "rb") as f:
            first, last, n, damage = None, None, 0, None
            try:
                # A file cut short has no summary to seek to: read it front to back.
                reader = NonSeekingReader(f) if damaged else make_reader(f)
                for schema, channel, message in reader.iter_messages(log_time_order=not damaged):
                    t = topics.setdefault(channel.topic, {"count": 0, "type": schema.name if schema else "",
                                                          "encoding": channel.message_encoding})
                    t["count"] += 1
                    n += 1
                    first = message.log_time if first is None else min(first, message.log_time)
                    last = message.log_time if last is None else max(last, message.log_time)
            except Exception as e:  # noqa: BLE001 - the damage is what is reported
                if not damaged:
                    raise
                damage = f"{type(e).__name__}: {e}"
            files.append({"count": n, "first": first, "last": last, "damage": damage})
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
    elif sys.argv[1] == "--damaged":
        print(json.dumps(mcap_files(sys.argv[2:], damaged=True)))
    else:
        print(json.dumps(mcap_files(sys.argv[1:])))
