#!/usr/bin/env bash
# Live benchmark of the graph (issue: the live node graph): two cameras replaying synthetic frames
# (camera_driver source `files`, looped) at 640x480/30 fps and 1920x1200/60 fps, SECONDS each,
# as separate processes and composed, launched by `xsurf launch` from the committed launch file,
# inside ../shared/tools/netns-run. A Cyclone DDS probe measures stamp -> profile latency and
# lost frames; CPU and peak RSS per process come from /proc. Prints one JSON line per run and a
# table. Needs the venv of the tests (`bash scripts/setup-venv.sh`).
# usage: bash scripts/bench-live.sh [SECONDS] [SIZES] [CLOUD_RATE_HZ] [MESH_RATE_HZ]
#   SIZES: "640x480 1920x1200" (default both); CLOUD_RATE_HZ: the meshers' growing cloud (default 1);
#   MESH_RATE_HZ: the meshers' growing surface (default 2, the node's default)
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-20}
sizes=${2:-640x480 1920x1200}
cloud_rate=${3:-1.0}
mesh_rate=${4:-2.0}
# The growing surface's sample stride (the mesher's mesh_preview_stride).
mesh_stride=${MESH_STRIDE:-4}
# A profile waits for the first table -> carm sample after its image's stamp (interpolation, no
# extrapolation), so the tf rate bounds the latency: 100 Hz adds up to 10 ms.
tf_rate=${TF_RATE:-100.0}
# ... unless the triangulators may extrapolate the travel past the newest sample (seconds).
extrapolation=${EXTRAPOLATION_S:-0.0}
cargo build --release -p xsurf-nodes --bins >/dev/null
bin=$PWD/target/release
work=$(mktemp -d /tmp/xsurf-bench-live.XXXXXX)
netns=$PWD/../shared/tools/netns-run
results=$work/results.jsonl
for size in $sizes; do
  fps=30
  [[ $size == 1920x1200 ]] && fps=60
  frames=$work/frames_$size
  "$bin/xsurf" synth pyramid -o "$frames" --size "$size" --frames 30 >/dev/null
  w=${size%x*} h=${size#*x}
  params=$work/params_$size.yaml
  cat >"$params" <<YAML
/**:
  ros__parameters:
    laser_plane: [0.0, 1.0, 0.0, 0.0]
/cam1/camera_driver:
  ros__parameters: {source: files, files: $frames/cam1, loop_files: true, fps: $fps}
/cam2/camera_driver:
  ros__parameters: {source: files, files: $frames/cam2, loop_files: true, fps: $fps}
/c_arm_pose:
  ros__parameters: {speed: 0.07, travel_start_m: -2.0, travel_end_m: 2.0, start_delay_s: 1.0, rate_hz: $tf_rate}
/**/mesher:
  ros__parameters: {cloud_rate_hz: $cloud_rate, mesh_rate_hz: $mesh_rate, mesh_preview_stride: $mesh_stride}
/**/triangulator:
  ros__parameters: {max_extrapolation_s: $extrapolation}
YAML
  for mode in separate composed; do
    echo "== $size @ $fps fps, $mode, ${secs} s, tf $tf_rate Hz, extrapolation $extrapolation s, cloud $cloud_rate Hz, mesh $mesh_rate Hz (stride $mesh_stride)" >&2
    "$netns" .venv/bin/python scripts/bench_live_probe.py "$bin" launch-config/xsurf.launch.yaml "$params" \
      "$mode" "$secs" "$fps" "$work/$size-$mode" | tee -a "$results"
  done
done
.venv/bin/python - "$results" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("\nLatency image stamp -> profile: 'published' = the node's DDS write returned (XSURF_LATENCY_LOG);")
print("'received' = a Cyclone DDS probe in Python took it (adds transport and the probe's scheduling).")
print("\n| run | frames expected (2 cams) | profiles | lost | published p50 / p99 / max ms | received p50 / p99 / max ms | CPU % (total) | peak RSS MiB (max) |")
print("|---|---|---|---|---|---|---|---|")
for r in rows:
    c = r["cameras"]
    size = "640x480" if r["fps"] == 30 else "1920x1200"
    exp = sum(v["frames_expected"] for v in c.values())
    got = sum(v["profiles"] for v in c.values())
    lost = sum(v["lost_in_sequence"] for v in c.values())
    p50 = max(v["latency_ms_p50"] for v in c.values())
    p99 = max(v["latency_ms_p99"] for v in c.values())
    mx = max(v["latency_ms_max"] for v in c.values())
    q50 = max(v["publish_ms_p50"] for v in c.values())
    q99 = max(v["publish_ms_p99"] for v in c.values())
    qmx = max(v["publish_ms_max"] for v in c.values())
    cpu = sum(p["cpu_percent"] for p in r["processes"].values())
    rss = max((p["peak_rss_mib"] for p in r["processes"].values()), default=0)
    print(f"| {size} @ {r['fps']:.0f} fps {r['mode']} | {exp} | {got} | {lost} | {q50} / {q99} / {qmx} | {p50} / {p99} / {mx} | {cpu:.0f} | {rss} |")
PY
echo "details: $results" >&2
