#!/usr/bin/env python3
"""Live latency and throughput of the graph (run by scripts/bench-live.sh inside netns-run).

Starts `xsurf launch LAUNCH [--composed] params:=PARAMS`, waits for the first profile, then for
SECONDS records every /camN/profile (PointCloud2) a Cyclone DDS probe receives: the latency is
the receive time minus the profile's stamp (= the image's exposure stamp, so it covers the image
crossing DDS, edge detection, triangulation and the profile crossing DDS to the probe). Frames
lost are the holes in each camera's stamp grid (the files source stamps at exact periods). CPU
per process from /proc/<pid>/stat over the window, peak RSS (VmHWM) at its end.

The graph also logs, through XSURF_LATENCY_LOG, the moment each profile's DDS write returned in
the node that published it: `publish_ms_*` is that time minus the stamp, over the same window,
without the probe's own transport and Python scheduling (the `tf_baseline` figures show what
those add). Prints one JSON line.
usage: bench_live_probe.py BIN_DIR LAUNCH PARAMS MODE SECONDS FPS OUT
"""
import json
import os
import pathlib
import signal
import subprocess
import sys
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests/py"))
from ros_types import PointCloud2, TFMessage  # noqa: E402

TICK = os.sysconf("SC_CLK_TCK")


def descendants(pid):
    kids = {}
    for d in pathlib.Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            kids.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        for c in kids.get(p, []):
            out.append(c)
            todo.append(c)
    return out


def label(pid):
    try:
        argv = (pathlib.Path("/proc") / str(pid) / "cmdline").read_bytes().split(b"\0")
    except OSError:
        return None
    argv = [a.decode() for a in argv if a]
    if not argv:
        return None
    name = os.path.basename(argv[0])
    if name == "xsurf" and len(argv) > 1 and argv[1] == "compose":
        return "compose (all nodes)"
    ns = next((a.split(":=", 1)[1] for a in argv if a.startswith("__ns:=")), "/")
    return (ns.rstrip("/") + "/" + name) if ns != "/" else "/" + name


def cpu(pid):
    try:
        f = (pathlib.Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()
        return (int(f[11]) + int(f[12])) / TICK
    except (OSError, IndexError):
        return None


def hwm(pid):
    try:
        for line in (pathlib.Path("/proc") / str(pid) / "status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def stop(proc, timeout, killed=-9):
    """SIGTERM to the launcher, then SIGKILL after `timeout` s; its exit code, or `killed`."""
    proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return killed


def pct(v, q):
    if not v:
        return None
    v = sorted(v)
    return v[min(len(v) - 1, int(q * len(v)))]


def main(bin_dir, launch, params, mode, seconds, fps, out):
    seconds, fps = float(seconds), float(fps)
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    dp = DomainParticipant(0)
    qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(200))
    readers = {c: DataReader(dp, Topic(dp, f"rt/{c}/profile", PointCloud2), qos=qos) for c in ("cam1", "cam2")}
    # /tf is stamped when c_arm_pose publishes it: its latency is the transport-and-probe baseline.
    tf_reader = DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=qos)
    tf_lat = []
    args = [str(pathlib.Path(bin_dir) / "xsurf"), "launch", launch, f"params:={params}"]
    if mode == "composed":
        args.insert(3, "--composed")
    log = open(out / f"launch-{mode}.log", "w")
    latency_log = out / f"latency-{mode}.log"
    latency_log.unlink(missing_ok=True)
    env = dict(os.environ, ROS_LOCALHOST_ONLY="1", XSURF_LATENCY_LOG=str(latency_log))
    proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=env)
    # Wait for the first profile from each camera.
    t_end = time.time() + 60
    seen = set()
    while time.time() < t_end and len(seen) < 2:
        for c, r in readers.items():
            if r.take(N=50):
                seen.add(c)
        time.sleep(0.01)
    time.sleep(1.0)
    for r in [*readers.values(), tf_reader]:
        r.take(N=1000)
    pids = [p for p in descendants(proc.pid) if label(p)]
    cpu0 = {p: cpu(p) for p in pids}
    t0 = time.time()
    t0_ns = time.time_ns()
    lat = {c: [] for c in readers}
    stamps = {c: [] for c in readers}
    while time.time() - t0 < seconds:
        for c, r in readers.items():
            for s in r.take(N=100):
                if isinstance(s, PointCloud2):
                    now = time.time_ns()
                    st = s.header.stamp.sec * 1_000_000_000 + s.header.stamp.nanosec
                    lat[c].append((now - st) / 1e6)
                    stamps[c].append(st)
        for s in tf_reader.take(N=100):
            if isinstance(s, TFMessage) and s.transforms:
                st = s.transforms[0].header.stamp
                tf_lat.append((time.time_ns() - (st.sec * 1_000_000_000 + st.nanosec)) / 1e6)
        time.sleep(0.0005)
    window = time.time() - t0
    t1_ns = time.time_ns()
    procs = {}
    for p in pids:
        c1 = cpu(p)
        if c1 is not None and cpu0.get(p) is not None:
            procs[label(p)] = {"cpu_percent": round(100 * (c1 - cpu0[p]) / window, 1), "peak_rss_mib": round((hwm(p) or 0) / 2**20, 1)}
    code = stop(proc, 30)
    period = 1e9 / fps
    result = {"tf_baseline_ms_p50": round(pct(tf_lat, 0.5) or -1, 2), "tf_baseline_ms_p99": round(pct(tf_lat, 0.99) or -1, 2), "mode": mode, "fps": fps, "window_s": round(window, 2), "launch_exit": code, "cameras": {}, "processes": procs}
    published = {c: [] for c in readers}
    if latency_log.exists():
        for line in latency_log.read_text().splitlines():
            parts = line.split()
            if len(parts) != 3:
                continue
            topic, stamp, at = parts[0], int(parts[1]), int(parts[2])
            c = topic.strip("/").split("/")[0]
            if topic.endswith("/profile") and c in published and t0_ns <= at <= t1_ns:
                published[c].append((at - stamp) / 1e6)
    for c in readers:
        st = sorted(set(stamps[c]))
        expected = int(round((st[-1] - st[0]) / period)) + 1 if st else 0
        result["cameras"][c] = {
            "frames_expected": int(round(window * fps)),
            "profiles": len(lat[c]),
            "lost_in_sequence": max(0, expected - len(st)),
            "latency_ms_p50": round(pct(lat[c], 0.5) or -1, 2),
            "latency_ms_p99": round(pct(lat[c], 0.99) or -1, 2),
            "latency_ms_max": round(max(lat[c]) if lat[c] else -1, 2),
            "published": len(published[c]),
            "publish_ms_p50": round(pct(published[c], 0.5) or -1, 2),
            "publish_ms_p99": round(pct(published[c], 0.99) or -1, 2),
            "publish_ms_max": round(max(published[c]) if published[c] else -1, 2),
        }
    text = (out / f"launch-{mode}.log").read_text(errors="replace")
    result["dropped_while_busy"] = [l.split("] ", 1)[-1] for l in text.splitlines() if "dropped while a node was busy" in l]
    # Each node's time in its own code, as the host logs it at shutdown (the whole run, start-up
    # included): per-node CPU also when the nodes share one process.
    busy = {}
    for l in text.splitlines():
        if "busy " in l and "% of a core" in l:
            msg = l.split("]: ", 1)[-1]
            name = msg.split(":", 1)[0]
            busy[name] = float(msg.split("busy ", 1)[1].split(" %", 1)[0])
    result["node_busy_percent"] = busy
    print(json.dumps(result))


if __name__ == "__main__":
    main(*sys.argv[1:])
