#!/usr/bin/env python3
"""Scan to view (run by scripts/bench-merge.sh inside netns-run): how long after END the merged
surface reaches a DDS peer.

Starts `xsurf launch LAUNCH [--composed] params:=PARAMS`, then SCANS times asks c_arm_pose for a
scan on /scan/request (START) as a hospital controller would, and records, as a Cyclone DDS
probe, when it receives the scan's END on /scan/events and the scan's merged surface on
/surface/mesh and /surface/cloud (the merger publishes both from the same merge, the mesh last).
A full body's mesh Marker is some 40 MB of Point structs, which Python would take seconds to
decode: the probe reads it as a type of the Marker's first fields only (header, ns, id, type,
action), so a Marker is decoded in microseconds and its time is that of its arrival. The
latency is a surface's receive time minus the END's receive time (and, beside it, minus the
END's stamp). Prints one JSON line.
usage: bench_merge_probe.py BIN_DIR LAUNCH PARAMS MODE SCANS OUT
"""
import json
import os
import pathlib
import subprocess
import sys
import threading
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests/py"))
from bench_live_probe import pct, stop  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402

from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import int32  # noqa: E402
from ros_types import Header, PointCloud2, ScanEvent, Time  # noqa: E402

START, END = 0, 1


@dataclass
class MarkerHead(IdlStruct, typename="visualization_msgs::msg::dds_::Marker_"):
    """visualization_msgs/Marker up to its action: CDR is read field by field, so the rest of
    the sample (the pose, the points, ...) is left undecoded. The graph's writers send no
    XTypes type information, so Cyclone DDS matches the reader by the type's name."""
    header: Header = field(default_factory=Header)
    ns: str = ""
    id: int32 = 0
    type: int32 = 0
    action: int32 = 0


def wait_for(pred, timeout):
    t = time.time() + timeout
    while time.time() < t:
        r = pred()
        if r is not None:
            return r
        time.sleep(0.002)
    return None


def main(bin_dir, launch, params, mode, scans, out):
    scans = int(scans)
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    dp = DomainParticipant(0)
    reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
    events = DataReader(dp, Topic(dp, "rt/scan/events", ScanEvent), qos=reliable)
    last = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1))
    surfaces = DataReader(dp, Topic(dp, "rt/surface/cloud", PointCloud2), qos=last)
    meshes = DataReader(dp, Topic(dp, "rt/surface/mesh", MarkerHead), qos=last)
    request = DataWriter(dp, Topic(dp, "rt/scan/request", ScanEvent), qos=reliable)
    args = [str(pathlib.Path(bin_dir) / "xsurf"), "launch", launch, f"params:={params}"]
    if mode == "composed":
        args.insert(3, "--composed")
    log = open(out / f"launch-{mode}.log", "w")
    env = dict(os.environ, ROS_LOCALHOST_ONLY="1")
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)

    def copy_log():
        # Each line with the time it was read, to place the nodes' steps between END and the surface.
        for line in proc.stdout:
            log.write(f"{time.time():.3f} {line.decode(errors='replace')}")
            log.flush()

    threading.Thread(target=copy_log, daemon=True).start()
    if wait_for(lambda: True if request.get_matched_subscriptions() else None, 60) is None:
        proc.kill()
        sys.exit("c_arm_pose did not subscribe /scan/request in 60 s")
    time.sleep(3.0)  # the cameras and the chain up
    rows = []
    for k in range(scans):
        events.take(N=100)
        surfaces.take(N=10)
        meshes.take(N=10)
        now = time.time()
        start_stamp = now
        request.write(ScanEvent(header=Header(stamp=Time(sec=int(now), nanosec=int((now % 1) * 1e9)), frame_id="table"), scan_id=0, event=START))

        def end_event():
            for s in events.take(N=10):
                if isinstance(s, ScanEvent) and s.event == END:
                    return (time.time(), s.scan_id, s.header.stamp.sec + s.header.stamp.nanosec * 1e-9)
            return None

        end = wait_for(end_event, 120)
        if end is None:
            rows.append({"scan": k, "error": "no END in 120 s"})
            continue
        t_end, scan_id, end_stamp = end

        # Both surfaces, each the first time it is seen: polled in turn, every 2 ms.
        got = {}

        def surfaces_in():
            for name, reader, kind in (("cloud", surfaces, PointCloud2), ("mesh", meshes, MarkerHead)):
                for s in reader.take(N=10):
                    if not isinstance(s, kind) or name in got:
                        continue
                    # The merged surface is stamped with the scan's last frame, before its END.
                    st = s.header.stamp.sec + s.header.stamp.nanosec * 1e-9
                    if start_stamp < st <= end_stamp:
                        got[name] = (time.time(), s.width * s.height if kind is PointCloud2 else None)
            return True if len(got) == 2 else None

        wait_for(surfaces_in, 30)
        row = {"scan": scan_id}
        for name in ("mesh", "cloud"):
            if name not in got:
                row.setdefault("error", []).append(f"no /surface/{name} in 30 s after END")
                continue
            t_surface, points = got[name]
            row[f"{name}_after_end_received_ms"] = round((t_surface - t_end) * 1e3, 1)
            row[f"{name}_after_end_stamp_ms"] = round((t_surface - end_stamp) * 1e3, 1)
            if points is not None:
                row["points"] = points
        rows.append(row)
        time.sleep(1.0)
    code = stop(proc, 30)
    summary = {"mode": mode, "scans": rows, "launch_exit": code}
    for name in ("mesh", "cloud"):
        lat = [r[f"{name}_after_end_received_ms"] for r in rows if f"{name}_after_end_received_ms" in r]
        lat_stamp = [r[f"{name}_after_end_stamp_ms"] for r in rows if f"{name}_after_end_stamp_ms" in r]
        summary.update({f"{name}_after_end_received_ms_p50": pct(lat, 0.5),
                        f"{name}_after_end_received_ms_p95": pct(lat, 0.95),
                        f"{name}_after_end_received_ms_max": max(lat) if lat else None,
                        f"{name}_after_end_stamp_ms_p50": pct(lat_stamp, 0.5),
                        f"{name}_after_end_stamp_ms_p95": pct(lat_stamp, 0.95)})
    print(json.dumps(summary))


if __name__ == "__main__":
    main(*sys.argv[1:])
