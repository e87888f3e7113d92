#!/usr/bin/env python3
"""A long run of the graph (issue 24, item 6; run by scripts/soak.sh inside netns-run).

Starts `xsurf launch LAUNCH [--composed] params:=PARAMS` and, for SECONDS, asks c_arm_pose for a
new scan (START on /scan/request, from this Cyclone DDS peer) as soon as the merger has written
the last one: back-to-back scans. Every 5 s it reads each process's peak resident memory since the
last reading (VmHWM, which it then resets through /proc/PID/clear_refs, so that a scan's surface
held for a moment between two readings is not missed) and its resident memory at that moment
(VmRSS, the floor the peaks stand on).
At the end it stops the launcher with SIGTERM and reads every scan's scan_report.json.
Prints one JSON line: scans asked and written, frames sent / received / lost (in transport,
refused, never sent) summed over scans and cameras, and per process the largest resident memory
of each minute, and its growth from the first minute after the warm-up (the first WARMUP s) to
the last.
usage: soak.py BIN_DIR LAUNCH PARAMS MODE SECONDS FILES OUT [WARMUP]
"""
import json
import os
import pathlib
import subprocess
import sys
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests/py"))
from bench_live_probe import descendants, label, stop  # noqa: E402
from ros_types import Header, ScanEvent, Time  # noqa: E402


def memory(pid):
    """(peak resident bytes since the last call, resident bytes now, whether the peak is exact).

    The peak is VmHWM, reset after reading by writing 5 to /proc/PID/clear_refs (Linux >= 4.0);
    where that is refused, the peak is the resident memory now (a sample, as before)."""
    proc = pathlib.Path("/proc") / str(pid)
    try:
        status = dict(line.split(":", 1) for line in (proc / "status").read_text().splitlines() if ":" in line)
        hwm, now = (int(status[k].split()[0]) * 1024 for k in ("VmHWM", "VmRSS"))
    except (OSError, KeyError, ValueError):
        return None
    try:
        (proc / "clear_refs").write_text("5")
        return hwm, now, True
    except OSError:
        return now, now, False


def trend(samples):
    """The least-squares slope of (t, rss) samples, as % of their mean per 600 s."""
    n = len(samples)
    if n < 3:
        return None
    mt = sum(t for t, _ in samples) / n
    mr = sum(r for _, r in samples) / n
    var = sum((t - mt) ** 2 for t, _ in samples)
    slope = sum((t - mt) * (r - mr) for t, r in samples) / var if var > 0 else 0.0
    return round(100 * slope * 600 / mr, 1)


def main(bin_dir, launch, params, mode, seconds, files, out, warmup="60"):
    seconds, warmup, files, out = float(seconds), float(warmup), pathlib.Path(files), pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    args = [str(pathlib.Path(bin_dir) / "xsurf"), "launch", launch, f"params:={params}"]
    if mode == "composed":
        args.insert(3, "--composed")
    log = open(out / "launch.log", "w")
    launcher = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ, ROS_LOCALHOST_ONLY="1"))
    dp = DomainParticipant(0)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
    request = DataWriter(dp, Topic(dp, "rt/scan/request", ScanEvent), qos=qos)
    t0 = time.time()
    samples = {}  # label -> [(t, peak since the last reading, rss now)]
    exact = True
    next_sample, asked, last_asked_for = 0.0, 1, 1  # scan 1 starts by itself
    while time.time() - t0 < seconds and launcher.poll() is None:
        now = time.time() - t0
        if now >= next_sample:
            next_sample = now + 5.0
            for p in descendants(launcher.pid):
                name, m = label(p), memory(p)
                if name and m:
                    samples.setdefault(name, []).append((now, m[0], m[1]))
                    exact = exact and m[2]
        # The scan just asked for is written: ask for the next one.
        if (files / f"scan_{last_asked_for}" / "scan_report.json").is_file():
            t = time.time()
            request.write(ScanEvent(header=Header(stamp=Time(sec=int(t), nanosec=int((t % 1) * 1e9)), frame_id="table"),
                                    scan_id=0, event=0))
            asked += 1
            last_asked_for += 1
        time.sleep(0.2)
    exit_code = stop(launcher, 60, killed="killed")
    totals = {"frames_sent": 0, "frames_received": 0, "frames_lost": 0, "frames_lost_in_transport": 0,
              "frames_refused_upstream": 0, "frames_not_sent": 0}
    written, incomplete, missing, cut = 0, 0, 0, 0
    for k in range(1, last_asked_for + 1):
        f = files / f"scan_{k}" / "scan_report.json"
        if not f.is_file():
            continue
        r = json.loads(f.read_text())
        if any(c.get("end") is None for c in r["cameras"]):
            cut += 1  # the scan the stop interrupted (merged at shutdown): not in the totals
            continue
        written += (files / f"scan_{k}" / "merged.ply").is_file()
        incomplete += len(r["incomplete"])
        missing += len(r["missing"])
        for c in r["cameras"]:
            for key in totals:
                totals[key] += c.get(key) or 0
    # Within a minute the memory rises and falls with each scan's surface, so the growth is
    # measured between the peaks of the first minute after the warm-up and of the last minute.
    figures = {}
    for name, s in sorted(samples.items()):
        minutes = {}
        for t, peak, now in s:
            minutes.setdefault(int(t // 60), []).append((t, peak, now))
        by_minute = [max(p for _, p, _ in minutes[m]) for m in sorted(minutes)]
        floor_by_minute = [min(n for _, _, n in minutes[m]) for m in sorted(minutes)]
        after = [max(p for _, p, _ in minutes[m]) for m in sorted(minutes) if m * 60 >= warmup]
        if len(after) >= 2:
            figures[name] = {"rss_max_first_minute_after_warmup_mib": round(after[0] / 2**20, 1),
                            "rss_max_last_minute_mib": round(after[-1] / 2**20, 1),
                            "rss_max_mib": round(max(after) / 2**20, 1),
                            "growth_percent": round(100 * (after[-1] - after[0]) / after[0], 1),
                            # Over a long run: the largest of the first five minutes after the
                            # warm-up against the largest of the last five (the band a scan's
                            # surface moves in, compared at both ends).
                            "growth_5_min_percent": (round(100 * (max(after[-5:]) - max(after[:5])) / max(after[:5]), 1)
                                                     if len(after) >= 10 else None),
                            "rss_max_by_minute_mib": [round(r / 2**20) for r in by_minute],
                            # The least resident memory of each minute: what stays between scans.
                            "rss_min_by_minute_mib": [round(r / 2**20) for r in floor_by_minute],
                            # Least-squares trend of every peak after the warm-up, % per 10 min.
                            "trend_percent_per_10_min": trend([(t, p) for t, p, _ in s if t >= warmup])}
    print(json.dumps({"mode": mode, "seconds": seconds, "launcher_exit": exit_code, "scans_asked": asked,
                      "scans_reported": sum((files / f"scan_{k}" / "scan_report.json").is_file() for k in range(1, last_asked_for + 1)),
                      "surfaces_written": written, "scans_cut_by_the_stop": cut, "cameras_incomplete": incomplete, "cameras_missing": missing,
                      **totals, "peaks_exact": exact, "memory": figures}))


if __name__ == "__main__":
    main(*sys.argv[1:9])
