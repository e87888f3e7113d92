#!/usr/bin/env python3
"""Scan to view (run by scripts/bench-merge.sh inside netns-run): how long after END the merged
surface reaches a DDS peer.

Starts `xsurf launch LAUNCH [--composed] params:=PARAMS`, then SCANS times asks c_arm_pose for a
scan on /scan/request (START) as a hospital controller would, and records, as a Cyclone DDS
probe, when it receives the scan's END on /scan/events and the scan's merged surface on
/surface/cloud (the merger publishes it with /surface/mesh, from the same merge; a full body's
mesh Marker is some 40 MB of Point structs, which the Python probe takes seconds to decode, so
the cloud, a byte array, times the arrival; the Marker's size is computed, not measured). The latency is the cloud's receive time minus the
END's receive time (and, beside it, minus the END's stamp). Prints one JSON line.
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
from ros_types import Header, PointCloud2, ScanEvent, Time  # noqa: E402

START, END = 0, 1


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
    surfaces = DataReader(dp, Topic(dp, "rt/surface/cloud", PointCloud2), qos=Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1)))
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

        def surface():
            for s in surfaces.take(N=10):
                st = s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 if isinstance(s, PointCloud2) else 0
                # The merged cloud is stamped with the scan's last frame, before its END.
                if isinstance(s, PointCloud2) and start_stamp < st <= end_stamp:
                    return (time.time(), s.width * s.height)
            return None

        got = wait_for(surface, 30)
        if got is None:
            rows.append({"scan": scan_id, "error": "no /surface/cloud in 30 s after END"})
            continue
        t_surface, points = got
        rows.append({"scan": scan_id, "after_end_received_ms": round((t_surface - t_end) * 1e3, 1),
                     "after_end_stamp_ms": round((t_surface - end_stamp) * 1e3, 1), "points": points})
        time.sleep(1.0)
    code = stop(proc, 30)
    lat = [r["after_end_received_ms"] for r in rows if "after_end_received_ms" in r]
    lat_stamp = [r["after_end_stamp_ms"] for r in rows if "after_end_stamp_ms" in r]
    print(json.dumps({"mode": mode, "scans": rows, "launch_exit": code,
                      "after_end_received_ms_p50": pct(lat, 0.5), "after_end_received_ms_p95": pct(lat, 0.95),
                      "after_end_received_ms_max": max(lat) if lat else None,
                      "after_end_stamp_ms_p50": pct(lat_stamp, 0.5), "after_end_stamp_ms_p95": pct(lat_stamp, 0.95)}))


if __name__ == "__main__":
    main(*sys.argv[1:])
