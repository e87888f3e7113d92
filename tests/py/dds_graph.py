#!/usr/bin/env python3
"""A two-camera-free DDS graph test, run inside ../shared/tools/netns-run by tests/dds.rs.

Our nodes run as separate processes: `edge_detector` and `triangulator` in namespace /cam1
(with a params file and a remap of `profile` to `profile_remapped`), and a second
`edge_detector` in /cam9. `xsurf bag play` publishes a synthetic scan's images, camera_info
and tf. This script is an independent DDS peer (Cyclone DDS):
  - it subscribes /cam1/profile_remapped (sensor_msgs/msg/PointCloud2, best effort) and /tf
    (tf2_msgs/msg/TFMessage) and checks what rviz2 checks (sizes, fields);
  - it publishes a sensor_msgs/msg/Image with a line at a known column on /cam9/image_raw and
    checks the LaserLine our edge_detector answers with;
  - it publishes the same line as sensor_msgs/msg/CompressedImage (PNG and JPEG made by Pillow,
    image_transport's format strings, and one truncated JPEG) on /cam8/image_raw/compressed to an
    edge_detector with image_transport:=compressed.
It writes the received profile points (float32 x y z, little-endian) to OUT/points.f32 and a
summary to OUT/summary.json; the Rust test compares the points with the ground truth.
With MODE `composed`, the /cam1 nodes run in one `xsurf compose` process instead (the line passes
in memory between them and is still published on DDS).
usage: dds_graph.py BIN_DIR BAG PARAMS OUT [MODE]
"""
import json
import math
import os
import pathlib
import struct
import subprocess
import sys
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from ros_types import CompressedImage, Header, Image, LaserLine, PointCloud2, TFMessage, Time  # noqa: E402

BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(50))
RELIABLE = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100))


def main(bin_dir, bag, params, out, mode="separate"):
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    bin_dir = pathlib.Path(bin_dir)
    env = dict(os.environ, ROS_LOCALHOST_ONLY="1")
    logs = {}

    def start(name, *args):
        f = open(out / f"{name}.log", "w")
        logs[name] = out / f"{name}.log"
        return subprocess.Popen([str(bin_dir / args[0]), *args[1:]], stdout=f, stderr=subprocess.STDOUT, env=env)

    if mode == "composed":
        procs = [start("compose", "xsurf", "compose", "/cam1/edge_detector", "/cam1/triangulator", "--ros-args",
                       "--params-file", params, "-r", "profile:=profile_remapped")]
    else:
        procs = [
            start("edge_detector_cam1", "edge_detector", "--ros-args", "-r", "__ns:=/cam1", "--params-file", params),
            start("triangulator_cam1", "triangulator", "--ros-args", "-r", "__ns:=/cam1", "--params-file", params,
                  "-r", "profile:=profile_remapped"),
        ]
    procs.append(start("edge_detector_cam9", "edge_detector", "--ros-args", "-r", "__ns:=/cam9", "-p", "min_strength:=30.0"))
    procs.append(start("edge_detector_cam8", "edge_detector", "--ros-args", "-r", "__ns:=/cam8", "-p", "min_strength:=30.0",
                       "-p", "image_transport:=compressed"))
    dp = DomainParticipant(0)
    profile_reader = DataReader(dp, Topic(dp, "rt/cam1/profile_remapped", PointCloud2), qos=BEST_EFFORT)
    tf_reader = DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=BEST_EFFORT)
    line_reader = DataReader(dp, Topic(dp, "rt/cam9/laser_line", LaserLine), qos=RELIABLE)
    # /cam1/laser_line is observed too: composed nodes still publish their internal topics.
    line1_reader = DataReader(dp, Topic(dp, "rt/cam1/laser_line", LaserLine), qos=BEST_EFFORT)
    image_writer = DataWriter(dp, Topic(dp, "rt/cam9/image_raw", Image), qos=RELIABLE)
    line8_reader = DataReader(dp, Topic(dp, "rt/cam8/laser_line", LaserLine), qos=RELIABLE)
    compressed_writer = DataWriter(dp, Topic(dp, "rt/cam8/image_raw/compressed", CompressedImage), qos=RELIABLE)
    summary = {"cam1_lines": 0, "clouds": 0, "cloud_errors": [], "tf": 0, "tf_frames": set(), "lines": [],
               "compressed_lines": []}
    points = bytearray()

    def drain():
        for s in profile_reader.take(N=100):
            if not isinstance(s, PointCloud2):
                continue
            summary["clouds"] += 1
            names = [f.name for f in s.fields]
            if s.width * s.height * s.point_step != len(s.data) or names[:3] != ["x", "y", "z"] or any(f.datatype != 7 for f in s.fields[:3]):
                summary["cloud_errors"].append(f"bad cloud {s.width}x{s.height} step {s.point_step} len {len(s.data)} fields {names}")
                continue
            if s.header.frame_id != "table":
                summary["cloud_errors"].append(f"frame {s.header.frame_id}")
            data = bytes(s.data)
            for i in range(s.width * s.height):
                x, y, z = struct.unpack_from("<fff", data, i * s.point_step)
                if not math.isnan(x):
                    points.extend(struct.pack("<fff", x, y, z))
        for s in tf_reader.take(N=100):
            if isinstance(s, TFMessage):
                summary["tf"] += 1
                for t in s.transforms:
                    summary["tf_frames"].add(f"{t.header.frame_id}->{t.child_frame_id}")
        for s in line1_reader.take(N=100):
            if isinstance(s, LaserLine):
                summary["cam1_lines"] += 1
        for s in line8_reader.take(N=10):
            if isinstance(s, LaserLine):
                found = [u for u in s.u if not math.isnan(u)]
                summary["compressed_lines"].append({"found": len(found), "mean_u": sum(found) / len(found) if found else None,
                                                    "stamp": [s.header.stamp.sec, s.header.stamp.nanosec]})
        for s in line_reader.take(N=10):
            if isinstance(s, LaserLine):
                found = [u for u in s.u if not math.isnan(u)]
                summary["lines"].append({"samples": len(s.u), "found": len(found),
                                         "mean_u": sum(found) / len(found) if found else None,
                                         "frame_id": s.header.frame_id, "stamp": [s.header.stamp.sec, s.header.stamp.nanosec]})

    # Wait for the nodes to come up and match, then publish a known image to /cam9.
    time.sleep(3.0)
    w, h, col = 64, 8, 30.25
    data = []
    for _y in range(h):
        for x in range(w):
            data.append(int(round(10 + 200 * math.exp(-((x - col) ** 2) / (2 * 1.5 ** 2)))))
    for k in range(5):
        image_writer.write(Image(header=Header(stamp=Time(sec=100, nanosec=k), frame_id="cam9_optical_frame"),
                                 height=h, width=w, encoding="mono8", is_bigendian=0, step=w, data=data))
        time.sleep(0.2)
        drain()
    # The same line compressed by Pillow: PNG, a truncated JPEG (refused and counted), JPEG.
    from PIL import Image as PilImage
    import io
    pil = PilImage.frombytes("L", (w, h), bytes(data))
    encoded = []
    for fmt, kind in [("mono8; png compressed ", "PNG"), ("mono8; jpeg compressed ", "JPEG")]:
        buf = io.BytesIO()
        pil.save(buf, format=kind, **({"quality": 95} if kind == "JPEG" else {}))
        encoded.append((fmt, buf.getvalue()))
    frames = [encoded[0], ("jpeg", encoded[1][1][: len(encoded[1][1]) // 3]), encoded[1]]
    for k, (fmt, payload) in enumerate(frames):
        compressed_writer.write(CompressedImage(header=Header(stamp=Time(sec=150, nanosec=k), frame_id="cam8_optical_frame"),
                                                format=fmt, data=list(payload)))
        time.sleep(0.3)
        drain()
    # Parameter services, as `ros2 param` uses them.
    def param(*args):
        r = subprocess.run([str(bin_dir / "xsurf"), "param", *args], capture_output=True, text=True, env=env, timeout=60)
        return {"code": r.returncode, "out": r.stdout.strip(), "err": r.stderr.strip()}
    summary["param"] = {
        "list": param("list", "/cam9/edge_detector"),
        "get": param("get", "/cam9/edge_detector", "min_strength"),
        "set_bad_method": param("set", "/cam9/edge_detector", "method", "bogus"),
        "set_bad_type": param("set", "/cam9/edge_detector", "min_strength", "loud"),
        "set_high_threshold": param("set", "/cam9/edge_detector", "min_strength", "250.0"),
        "get_after": param("get", "/cam9/edge_detector", "min_strength"),
    }
    # With the threshold above the line's height, the same image now gives no line.
    time.sleep(0.5)
    drain()
    before = len(summary["lines"])
    for k in range(3):
        image_writer.write(Image(header=Header(stamp=Time(sec=200, nanosec=k), frame_id="cam9_optical_frame"),
                                 height=h, width=w, encoding="mono8", is_bigendian=0, step=w, data=data))
        time.sleep(0.2)
        drain()
    summary["lines_after_set"] = summary["lines"][before:]
    summary["lines"] = summary["lines"][:before]
    player = start("bag_play", "xsurf", "bag", "play", bag, "--delay", "1.0",
                   "--topics", "/cam1/image_raw,/cam1/camera_info,/tf,/tf_static")
    deadline = time.time() + 120
    while player.poll() is None and time.time() < deadline:
        drain()
        time.sleep(0.05)
    end = time.time() + 3.0
    while time.time() < end:
        drain()
        time.sleep(0.05)
    for p in procs:
        p.terminate()
    codes = []
    for p in procs:
        try:
            codes.append(p.wait(timeout=10))
        except subprocess.TimeoutExpired:
            p.kill()
            codes.append("killed")
    summary["player_exit"] = player.poll()
    summary["node_exits"] = codes
    summary["tf_frames"] = sorted(summary["tf_frames"])
    summary["points"] = len(points) // 12
    summary["logs"] = {k: str(v) for k, v in logs.items()}
    (out / "points.f32").write_bytes(points)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary))


if __name__ == "__main__":
    main(*sys.argv[1:6])
