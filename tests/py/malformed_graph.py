#!/usr/bin/env python3
"""Malformed messages from an independent DDS peer (Cyclone DDS) into the separate-process live
graph, then clean scans; run inside ../shared/tools/netns-run by tests/live.rs (issue 24).

`xsurf launch` runs the committed launch file (every node its own process, respawn on). Scan 1
starts by itself and is the clean reference. Then, ROUNDS times: this peer publishes a burst of
malformed messages on every topic the graph takes in (the images, camera_info, laser lines,
profiles and clouds of both cameras, /tf, /tf_static, scan events and requests, scan reports,
the encoder, placements, the radiograph), stamped now, then asks c_arm_pose for a scan on
/scan/request and waits until the merger has written it. Then SIGTERM to the launcher.
Prints a JSON summary: the scans written, the messages sent per topic, the launcher's exit code.
usage: malformed_graph.py BIN_DIR LAUNCH PARAMS OUT FILES ROUNDS
"""
import json
import math
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

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from ros_types import (CameraInfo, CompressedImage, Header, Image, JointState, LaserLine, PointCloud2,  # noqa: E402
                       PointField, Quaternion, ScanEvent, String, TFMessage, Time, Transform,
                       TransformStamped, Vector3)

RELIABLE = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100))
# Transient local as /tf_static is, so that the nodes' static subscriptions match.
STATIC = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1),
             Policy.Durability.TransientLocal)
NAN, INF = float("nan"), float("inf")
W, H = 320, 240


def now_header(frame_id):
    t = time.time()
    return Header(stamp=Time(sec=int(t), nanosec=int((t % 1) * 1e9)), frame_id=frame_id)


def xyz_fields(names=("x", "y", "z")):
    return [PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate(names)]


def cloud(header, height, width, data_len=None, point_step=12, fields=None):
    n = height * width * point_step if data_len is None else data_len
    return PointCloud2(header=header, height=height, width=width, fields=fields if fields is not None else xyz_fields(),
                       is_bigendian=False, point_step=point_step, row_step=(width * point_step) & 0xFFFFFFFF,
                       data=[0] * n, is_dense=False)


def tf(parent, child, t=(0.0, 0.0, 0.0), q=(0.0, 0.0, 0.0, 1.0)):
    return TFMessage(transforms=[TransformStamped(
        header=now_header(parent), child_frame_id=child,
        transform=Transform(translation=Vector3(*t), rotation=Quaternion(*q)))])


def poison(cam):
    """(topic suffix or absolute topic, type, message) of one burst for camera `cam`."""
    opt = f"{cam}_optical_frame"
    h = lambda: now_header(opt)  # noqa: E731
    nan_k = [NAN] * 9
    good_k = [300.0, 0, 160.0, 0, 300.0, 120.0, 0, 0, 1.0]
    img = f"/{cam}/image_raw"
    info = f"/{cam}/camera_info"
    line = f"/{cam}/laser_line"
    prof = f"/{cam}/profile"
    cl = f"/{cam}/cloud"
    return [
        # Images: bad strides, short data, unknown encodings, zero and absurd sizes, a size the
        # camera does not have, odd mono16 steps.
        (img, Image, Image(header=h(), height=H, width=W, encoding="mono8", step=100, data=[0] * (100 * H))),
        (img, Image, Image(header=h(), height=H, width=W, encoding="mono8", step=W, data=[0] * 1000)),
        (img, Image, Image(header=h(), height=H, width=W, encoding="bogus16", step=2 * W, data=[0] * (2 * W * H))),
        (img, Image, Image(header=h(), height=0, width=0, encoding="mono8", step=0, data=[])),
        (img, Image, Image(header=h(), height=100000, width=100000, encoding="mono8", step=100000, data=[])),
        (img, Image, Image(header=h(), height=8, width=64, encoding="mono8", step=64, data=[200] * 512)),
        (img, Image, Image(header=h(), height=H, width=W, encoding="mono16", step=2 * W - 1, data=[0] * ((2 * W - 1) * H))),
        (img, Image, Image(header=h(), height=H, width=W, encoding="rgb8", step=W, data=[0] * (W * H))),
        (f"/{cam}/image_raw/compressed", CompressedImage, CompressedImage(header=h(), format="jpeg", data=[0xFF, 0xD8, 1, 2, 3])),
        # camera_info: zeros, NaN intrinsics, a zero focal length, a short distortion vector.
        (info, CameraInfo, CameraInfo(header=h(), height=0, width=0)),
        (info, CameraInfo, CameraInfo(header=h(), height=H, width=W, distortion_model="plumb_bob", d=[0.0] * 5, k=nan_k)),
        (info, CameraInfo, CameraInfo(header=h(), height=H, width=W, distortion_model="plumb_bob", d=[0.0] * 5)),
        (info, CameraInfo, CameraInfo(header=h(), height=H, width=W, distortion_model="plumb_bob", d=[0.1, 0.2], k=good_k)),
        (info, CameraInfo, CameraInfo(header=h(), height=H, width=W, distortion_model="fisheye9", d=[NAN] * 4, k=good_k)),
        (info, CameraInfo, CameraInfo(header=h(), height=1 << 30, width=1 << 30, k=good_k)),
        # Laser lines: the one that once fixed a grid (0x0, orientation 9, 10 NaN samples),
        # sizes that contradict the camera, samples of unequal length, infinite samples.
        (line, LaserLine, LaserLine(header=h(), image_width=0, image_height=0, orientation=9,
                                    u=[NAN] * 10, v=[NAN] * 10, strength=[NAN] * 10, width=[NAN] * 10)),
        (line, LaserLine, LaserLine(header=h(), image_width=W, image_height=H, orientation=0,
                                    u=[1.0] * 10, v=[1.0] * 10, strength=[1.0] * 10, width=[1.0] * 10)),
        (line, LaserLine, LaserLine(header=h(), image_width=W, image_height=H, orientation=0,
                                    u=[1.0] * H, v=[1.0] * 10, strength=[1.0] * H, width=[1.0] * H)),
        (line, LaserLine, LaserLine(header=h(), image_width=W, image_height=H, orientation=0,
                                    u=[INF] * H, v=[-INF] * H, strength=[INF] * H, width=[NAN] * H)),
        (line, LaserLine, LaserLine(header=h(), image_width=64, image_height=8, orientation=0,
                                    u=[30.0] * 8, v=list(map(float, range(8))), strength=[200.0] * 8, width=[2.0] * 8)),
        # Profiles: no point step, short data, the wrong number of samples, no x field.
        (prof, PointCloud2, cloud(now_header("table"), H, 1, point_step=0)),
        (prof, PointCloud2, cloud(now_header("table"), H, 1, data_len=7)),
        (prof, PointCloud2, cloud(now_header("table"), 10, 1)),
        (prof, PointCloud2, cloud(now_header("table"), H, 1, fields=xyz_fields(("q", "y", "z")))),
        (prof, PointCloud2, cloud(now_header("table"), 0xFFFFFFFF, 0xFFFFFFFF, data_len=0)),
        # Clouds into the merger: malformed, and well formed with samples the camera has not.
        (cl, PointCloud2, cloud(now_header("table"), 7, 3, data_len=0)),
        (cl, PointCloud2, cloud(now_header("table"), 10, 5)),
        (cl, PointCloud2, cloud(now_header("table"), H, 3, fields=[])),
    ]


def shared():
    """The burst on the graph's shared topics."""
    ev = lambda e, sid=0: ScanEvent(header=now_header("table"), scan_id=sid, event=e)  # noqa: E731
    return [
        ("/tf", TFMessage, tf("table", "carm", t=(NAN, 0.0, 0.0))),
        ("/tf", TFMessage, tf("table", "carm", q=(0.0, 0.0, 0.0, 0.0))),
        ("/tf", TFMessage, tf("table", "carm", t=(INF, -INF, 0.0), q=(NAN, 0.0, 0.0, 1.0))),
        ("/tf", TFMessage, tf("carm", "cam1_optical_frame", t=(NAN, NAN, NAN))),
        ("/tf", TFMessage, TFMessage(transforms=[])),
        ("/tf", TFMessage, tf("", "", t=(0.0, 0.0, 0.0))),
        ("/tf_static", TFMessage, tf("carm", "cam2_optical_frame", q=(NAN, NAN, NAN, NAN))),
        ("/scan/events", ScanEvent, ev(7)),
        ("/scan/events", ScanEvent, ev(255, 4_000_000_000)),
        ("/scan/request", ScanEvent, ev(9)),
        ("/scan/report", String, String(data="not json {")),
        ("/scan/report", String, String(data='{"scan_id": "x", "camera": 5}')),
        ("/scan/report", String, String(data="[]")),
        ("/carm/encoder", JointState, JointState(header=now_header(""), name=["carm_travel"], position=[NAN])),
        ("/carm/encoder", JointState, JointState(header=now_header(""), name=["carm_travel", "x"], position=[0.1])),
        ("/surface/placements", TFMessage, tf("carm", "cam1_optical_frame", t=(NAN, 0.0, 0.0))),
        ("/xray/image", Image, Image(header=now_header("xray"), height=100, width=100, encoding="mono16", step=3, data=[0] * 10)),
        ("/xray/image", Image, Image(header=now_header("xray"), height=0, width=0, encoding="", step=0, data=[])),
    ]


def main(bin_dir, launch, params, out, files, rounds):
    out, files, rounds = pathlib.Path(out), pathlib.Path(files), int(rounds)
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, ROS_LOCALHOST_ONLY="1")
    log = open(out / "launch.log", "w")
    launcher = subprocess.Popen([str(pathlib.Path(bin_dir) / "xsurf"), "launch", launch, f"params:={params}"],
                                stdout=log, stderr=subprocess.STDOUT, env=env)
    dp = DomainParticipant(0)
    writers = {}

    def writer(topic, typ):
        if topic not in writers:
            qos = STATIC if topic == "/tf_static" else RELIABLE
            writers[topic] = [DataWriter(dp, Topic(dp, "rt" + topic, typ), qos=qos), 0]
        return writers[topic]

    def send(topic, typ, msg):
        w = writer(topic, typ)
        w[0].write(msg)
        w[1] += 1

    def wait_for(path, seconds):
        t0 = time.time()
        while time.time() - t0 < seconds:
            if path.is_file():
                return True
            if launcher.poll() is not None:
                return False
            time.sleep(0.1)
        return False

    summary = {"scans": [], "errors": []}
    try:
        drive(summary, writer, send, wait_for, files, rounds)
    except Exception as e:  # the graph is stopped and the summary printed whatever went wrong
        summary["errors"].append(f"the peer failed: {e!r}")
    launcher.terminate()
    try:
        summary["launcher_exit"] = launcher.wait(timeout=30)
    except subprocess.TimeoutExpired:
        launcher.kill()
        summary["launcher_exit"] = "killed"
    summary["sent"] = {t: n for t, (_, n) in sorted(writers.items()) if n}
    print(json.dumps(summary))


def drive(summary, writer, send, wait_for, files, rounds):
    """Scan 1 (clean), then `rounds` times a malformed burst and a requested scan."""
    # The writers exist (and match) before scan 1 ends, so the bursts are not lost to discovery.
    for topic, typ, _ in poison("cam1") + poison("cam2") + shared():
        writer(topic, typ)
    if wait_for(files / "scan_1" / "scan_report.json", 90):
        summary["scans"].append(1)
    else:
        summary["errors"].append("the clean scan 1 was never merged")
    request = writer("/scan/request", ScanEvent)
    for k in range(2, rounds + 2):
        if summary["errors"]:
            break
        # Twice, a little apart: once the nodes have settled after the last scan, and once more.
        for _ in range(2):
            for topic, typ, msg in poison("cam1") + poison("cam2") + shared():
                send(topic, typ, msg)
                time.sleep(0.002)
            time.sleep(0.3)
        time.sleep(0.5)
        request[0].write(ScanEvent(header=now_header("table"), scan_id=0, event=0))
        if wait_for(files / f"scan_{k}" / "scan_report.json", 60):
            summary["scans"].append(k)
        else:
            summary["errors"].append(f"scan {k} was never merged")
        time.sleep(0.5)


if __name__ == "__main__":
    main(*sys.argv[1:7])
