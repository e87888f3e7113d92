#!/usr/bin/env bash
# Benchmark (not a test) of scan to view (issue 22): full-body scans run live, each asked for by a
# Cyclone DDS peer on /scan/request. The two cameras replay a rendered full-body scan (`xsurf
# synth body`, 390 frames a camera at 0.124 m/s and 30 fps; camera_driver source `files`, looped:
# this machine cannot render two 640x480 cameras at 30 fps live), so each scan's grids have the
# full scan's size. The loop starts when each camera_driver starts, not at the scan's START, so
# the surfaces' geometry (and the points merged) is not measured here, only the timing. The peer records how
# long after it receives END it receives the merged surface on /surface/mesh and on /surface/cloud. Runs the graph as
# separate processes and composed, launched by `xsurf launch` from the committed launch file,
# inside ../shared/tools/netns-run. Needs the venv of the tests (`bash scripts/setup-venv.sh`).
# usage: bash scripts/bench-merge.sh [SCANS] [SIZE] [MODES]
#   SCANS: scans per mode (default 10); SIZE: 640x480 (default) or 1920x1200;
#   MODES: "separate composed" (default both)
#   REPUBLISH_S: the merger's republish_s (default 2); WORK: the work folder (default a new
#   one under /tmp); XSURF_BIN: prebuilt binaries
# The peer runs with Cyclone DDS's defaults; CYCLONEDDS_URI in the environment configures it (for
# instance a larger SocketReceiveBufferSize, as BENCHMARKS.md measured). The graph's nodes do not
# read it.
set -euo pipefail
cd "$(dirname "$0")/.."
scans=${1:-10}
size=${2:-640x480}
modes=${3:-separate composed}
# XSURF_BIN: the folder of binaries already built (a test's), instead of building them here.
if [[ -n ${XSURF_BIN:-} ]]; then
  bin=$XSURF_BIN
else
  cargo build --release -p xsurf-nodes --bins >/dev/null
  bin=$PWD/target/release
fi
work=${WORK:-$(mktemp -d /tmp/xsurf-bench-merge.XXXXXX)}
mkdir -p "$work"
netns=$PWD/../shared/tools/netns-run
frames=$work/frames
"$bin/xsurf" synth body -o "$frames" --size "$size" --speed 0.124 --frames 390 >/dev/null
params=$work/params.yaml
cat >"$params" <<YAML
/**:
  ros__parameters:
    laser_plane: [0.0, 1.0, 0.0, 0.0]
    output_dir: $work/scans
/cam1/camera_driver:
  ros__parameters: {source: files, files: $frames/cam1, loop_files: true, fps: 30.0}
/cam2/camera_driver:
  ros__parameters: {source: files, files: $frames/cam2, loop_files: true, fps: 30.0}
/**/triangulator:
  ros__parameters: {max_extrapolation_s: 0.012}
/**/mesher:
  ros__parameters: {cloud_rate_hz: 2.0}
/c_arm_pose:
  ros__parameters: {speed: 0.124, travel_start_m: -0.03, travel_end_m: 1.58, auto_start: false}
/merger:
  ros__parameters: {republish_s: ${REPUBLISH_S:-2.0}}
YAML
for mode in $modes; do
  echo "== $size, $mode, $scans scans" >&2
  "$netns" .venv/bin/python scripts/bench_merge_probe.py "$bin" launch-config/xsurf.launch.yaml "$params" \
    "$mode" "$scans" "$work/$mode" | tee -a "$work/results.jsonl"
done
echo "work folder: $work" >&2
