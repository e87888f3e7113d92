#!/usr/bin/env python3
"""Independent ROS 2 peers (Cyclone DDS) of our running graph, run inside
../shared/tools/netns-run by tests/rviz.rs.

MODE standin: an rviz2 stand-in. It subscribes, with the ROS 2 type names, best-effort readers
to /surface/cloud, /cam1/mesh, /tf and /cam1/image_raw, and /tf_static reliable and transient
local as rviz2 does, then starts the whole graph (`xsurf launch` of the committed launch file,
composed) and checks what rviz2 checks: PointCloud2 width*height*point_step == len(data),
row_step, fields x/y/z float32; Marker TRIANGLE_LIST with a multiple of 3 points and one colour
per point; Image step*height == len(data); every frame id resolvable to `table` through tf.

MODE publish: a hospital stack's CI. It starts only the processing nodes (edge_detector,
triangulator, mesher per camera, merger) and publishes a synthetic scan itself, message by
message at the original pace: the frames, camera_info, /tf, /tf_static and /scan/events read
from a bag with the `rosbags` package, then waits for the surface on /surface/cloud.

Both write the surface points (float32 x y z) to WORK/surface.f32 and a summary to
WORK/summary.json for the Rust test, which measures them against the ground truth.
usage: rviz_standin.py MODE BIN_DIR ROOT WORK PARAMS [BAG]
"""
import json
import math
import os
import pathlib
import signal
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
from ros_types import (CameraInfo, Header, Image, Marker, PointCloud2, Quaternion,  # noqa: E402
                       RegionOfInterest, ScanEvent, Time, Transform, TransformStamped, TFMessage, Vector3)

BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(20))
STATIC = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
             Policy.History.KeepLast(1))
RELIABLE = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100))


def check_cloud(s, errors):
    names = [f.name for f in s.fields]
    if s.width * s.height * s.point_step != len(s.data):
        errors.append(f"cloud: {s.width}x{s.height} x {s.point_step} != {len(s.data)} bytes")
    if s.row_step != s.width * s.point_step:
        errors.append(f"cloud: row_step {s.row_step} != {s.width} x {s.point_step}")
    if names[:3] != ["x", "y", "z"] or any(f.datatype != 7 or f.count != 1 for f in s.fields[:3]):
        errors.append(f"cloud: fields {names} are not x, y, z float32")


def cloud_points(s):
    data = bytes(s.data)
    out = bytearray()
    for i in range(s.width * s.height):
        x, y, z = struct.unpack_from("<fff", data, i * s.point_step)
        if not math.isnan(x):
            out.extend(struct.pack("<fff", x, y, z))
    return out


def resolvable(frame, edges):
    """True if `frame` chains to `table` through the tf edges (child -> parent)."""
    seen = set()
    while frame != "table":
        if frame in seen or frame not in edges:
            return False
        seen.add(frame)
        frame = edges[frame]
    return True


def launch(bin_dir, args, log):
    env = dict(os.environ, ROS_LOCALHOST_ONLY="1")
    return subprocess.Popen([str(bin_dir / "xsurf"), "launch", *args], stdout=log, stderr=subprocess.STDOUT, env=env)


def stop(proc):
    proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        return -9


def standin(bin_dir, root, work, params):
    dp = DomainParticipant(0)
    cloud_r = DataReader(dp, Topic(dp, "rt/surface/cloud", PointCloud2), qos=BEST_EFFORT)
    mesh_r = DataReader(dp, Topic(dp, "rt/cam1/mesh", Marker), qos=BEST_EFFORT)
    tf_r = DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=BEST_EFFORT)
    static_r = DataReader(dp, Topic(dp, "rt/tf_static", TFMessage), qos=STATIC)
    image_r = DataReader(dp, Topic(dp, "rt/cam1/image_raw", Image), qos=BEST_EFFORT)
    log = open(work / "launch.log", "w")
    proc = launch(bin_dir, [str(root / "launch-config/xsurf.launch.yaml"), "--composed", f"params:={params}"], log)
    s = {"errors": [], "clouds": 0, "meshes": 0, "images": 0, "tf": 0, "static": 0, "frames": set()}
    edges = {}
    surface = None
    deadline = time.time() + 90
    while time.time() < deadline and (surface is None or s["meshes"] == 0):
        for m in tf_r.take(N=200):
            if isinstance(m, TFMessage):
                s["tf"] += 1
                for t in m.transforms:
                    edges[t.child_frame_id] = t.header.frame_id
        for m in static_r.take(N=10):
            if isinstance(m, TFMessage):
                s["static"] += 1
                for t in m.transforms:
                    edges[t.child_frame_id] = t.header.frame_id
        for m in image_r.take(N=20):
            if isinstance(m, Image):
                s["images"] += 1
                s["frames"].add(m.header.frame_id)
                if m.step * m.height != len(m.data) or m.step < m.width:
                    s["errors"].append(f"image: step {m.step} x {m.height} != {len(m.data)}")
        for m in mesh_r.take(N=5):
            if isinstance(m, Marker) and m.action == 0:
                s["meshes"] += 1
                s["frames"].add(m.header.frame_id)
                if m.type != 11 or len(m.points) % 3 != 0 or not m.points:
                    s["errors"].append(f"mesh: type {m.type} with {len(m.points)} points")
                if len(m.colors) != len(m.points):
                    s["errors"].append(f"mesh: {len(m.colors)} colours for {len(m.points)} points")
                s["mesh_triangles"] = len(m.points) // 3
        for m in cloud_r.take(N=5):
            if isinstance(m, PointCloud2):
                s["clouds"] += 1
                s["frames"].add(m.header.frame_id)
                check_cloud(m, s["errors"])
                surface = cloud_points(m)
        time.sleep(0.05)
    s["launch_exit"] = stop(proc)
    s["unresolved"] = sorted(f for f in s["frames"] if not resolvable(f, edges))
    s["frames"] = sorted(s["frames"])
    s["edges"] = edges
    return s, surface


def to_header(h):
    return Header(stamp=Time(sec=int(h.stamp.sec), nanosec=int(h.stamp.nanosec)), frame_id=str(h.frame_id))


def to_tf(m):
    out = []
    for t in m.transforms:
        tr, q = t.transform.translation, t.transform.rotation
        out.append(TransformStamped(header=to_header(t.header), child_frame_id=str(t.child_frame_id),
                                    transform=Transform(translation=Vector3(x=tr.x, y=tr.y, z=tr.z),
                                                        rotation=Quaternion(x=q.x, y=q.y, z=q.z, w=q.w))))
    return TFMessage(transforms=out)


def publish(bin_dir, work, params, bag):
    from rosbags.highlevel import AnyReader

    launch_file = work / "processing.launch.yaml"
    nodes = []
    for cam in ("cam1", "cam2"):
        for exe in ("edge_detector", "triangulator", "mesher"):
            nodes.append(f"- node: {{exec: {exe}, namespace: {cam}, param: [{{from: {params}}}]}}")
    nodes.append(f"- node: {{exec: merger, param: [{{from: {params}}}]}}")
    launch_file.write_text("launch:\n" + "\n".join(nodes) + "\n")
    dp = DomainParticipant(0)
    cloud_r = DataReader(dp, Topic(dp, "rt/surface/cloud", PointCloud2), qos=BEST_EFFORT)
    writers = {}

    def writer(topic, kind, qos):
        if topic not in writers:
            writers[topic] = DataWriter(dp, Topic(dp, "rt" + topic, kind), qos=qos)
        return writers[topic]

    log = open(work / "launch.log", "w")
    proc = launch(bin_dir, [str(launch_file), "--composed"], log)
    time.sleep(4.0)  # the nodes come up and match
    s = {"errors": [], "published": 0, "clouds": 0}
    surface = None
    with AnyReader([pathlib.Path(bag)]) as reader:
        wanted = [c for c in reader.connections
                  if c.topic in ("/tf", "/tf_static", "/scan/events") or c.topic.endswith(("/image_raw", "/camera_info"))]
        t0_bag, t0 = None, time.time()
        for conn, t, raw in reader.messages(connections=wanted):
            m = reader.deserialize(raw, conn.msgtype)
            if t0_bag is None:
                t0_bag = t
            wait = (t - t0_bag) * 1e-9 - (time.time() - t0)
            if wait > 0:
                time.sleep(wait)
            topic = conn.topic
            if topic == "/tf_static":
                writer(topic, TFMessage, STATIC).write(to_tf(m))
            elif topic == "/tf":
                writer(topic, TFMessage, RELIABLE).write(to_tf(m))
            elif topic == "/scan/events":
                writer(topic, ScanEvent, RELIABLE).write(
                    ScanEvent(header=to_header(m.header), scan_id=int(m.scan_id), event=int(m.event)))
            elif topic.endswith("/image_raw"):
                writer(topic, Image, RELIABLE).write(
                    Image(header=to_header(m.header), height=int(m.height), width=int(m.width), encoding=str(m.encoding),
                          is_bigendian=int(m.is_bigendian), step=int(m.step), data=bytes(m.data)))
            else:
                r = m.roi
                writer(topic, CameraInfo, RELIABLE).write(
                    CameraInfo(header=to_header(m.header), height=int(m.height), width=int(m.width),
                               distortion_model=str(m.distortion_model), d=[float(v) for v in m.d],
                               k=[float(v) for v in m.k], r=[float(v) for v in m.r], p=[float(v) for v in m.p],
                               binning_x=int(m.binning_x), binning_y=int(m.binning_y),
                               roi=RegionOfInterest(x_offset=int(r.x_offset), y_offset=int(r.y_offset),
                                                    height=int(r.height), width=int(r.width),
                                                    do_rectify=bool(r.do_rectify))))
            s["published"] += 1
    deadline = time.time() + 30
    while time.time() < deadline and surface is None:
        for m in cloud_r.take(N=5):
            if isinstance(m, PointCloud2):
                s["clouds"] += 1
                check_cloud(m, s["errors"])
                surface = cloud_points(m)
        time.sleep(0.05)
    s["launch_exit"] = stop(proc)
    return s, surface


def main(mode, bin_dir, root, work, params, bag=None):
    work = pathlib.Path(work)
    work.mkdir(parents=True, exist_ok=True)
    if mode == "standin":
        s, surface = standin(pathlib.Path(bin_dir), pathlib.Path(root), work, params)
    else:
        s, surface = publish(pathlib.Path(bin_dir), work, params, bag)
    s["surface_points"] = 0 if surface is None else len(surface) // 12
    if surface is not None:
        (work / "surface.f32").write_bytes(bytes(surface))
    (work / "summary.json").write_text(json.dumps(s, indent=1))
    print(json.dumps({k: v for k, v in s.items() if k != "edges"}))


if __name__ == "__main__":
    main(*sys.argv[1:])
