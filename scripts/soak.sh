#!/usr/bin/env bash
# The long run of issue 24 (not a CI test; the figures are in BENCHMARKS.md): two cameras at
# 1920x1200 and 30 fps (camera_driver replaying a looped synthetic sequence, so that the
# cameras cost no rendering), back-to-back scans asked for by a Cyclone DDS peer as soon as the
# last one is written, for SECONDS (default 600), composed and then as separate processes,
# inside ../shared/tools/netns-run. Prints one JSON line per mode (scripts/soak.py).
# usage: bash scripts/soak.sh [SECONDS] [MODES]   (MODES default: "composed separate")
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-600}
modes=${2:-composed separate}
cargo build --release -p xsurf-nodes --bins >/dev/null
bin=$PWD/target/release
work=$(mktemp -d /tmp/xsurf-soak.XXXXXX)
frames=$work/frames
"$bin/xsurf" synth pyramid -o "$frames" --size 1920x1200 --frames 30 >/dev/null
for mode in $modes; do
  files=$work/$mode/files
  params=$work/params_$mode.yaml
  cat >"$params" <<YAML
/**:
  ros__parameters:
    laser_plane: [0.0, 1.0, 0.0, 0.0]
    output_dir: $files
/cam1/camera_driver:
  ros__parameters: {source: files, files: $frames/cam1, loop_files: true, fps: 30.0}
/cam2/camera_driver:
  ros__parameters: {source: files, files: $frames/cam2, loop_files: true, fps: 30.0}
/c_arm_pose:
  ros__parameters: {speed: 0.07, start_delay_s: 3.0}
/**/mesher:
  ros__parameters: {cloud_rate_hz: 1.0}
/merger:
  ros__parameters: {merge_delay_s: 1.0}
YAML
  echo "== soak: $mode, ${secs} s, 2 x 1920x1200 @ 30 fps" >&2
  ../shared/tools/netns-run .venv/bin/python scripts/soak.py "$bin" launch-config/xsurf.launch.yaml "$params" \
    "$mode" "$secs" "$files" "$work/$mode"
done
echo "(work files in $work)" >&2
