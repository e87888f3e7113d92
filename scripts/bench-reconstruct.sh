#!/usr/bin/env bash
# Benchmark (not a test): reconstruct full-body scans from bags and report wall time, frames per
# second per core and peak RSS, as in the study's Table 5.5. Two cases:
#   640   two 640x480 mono8 cameras, 390 frames each (1.61 m at 0.124 m/s and 30 fps);
#   1920h two 1920x1200 mono8 cameras, 107 frames each (0.452 m/s), cam2 hung on its side so
#         that its line is horizontal (`xsurf synth --horizontal cam2`).
# The study took 792 s from scan to view; the targets are in BENCHMARKS.md.
# usage: scripts/bench-reconstruct.sh [WORKDIR] [CASE...]   (the synthetic bags are cached there)
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:-target/bench-reconstruct}
shift || true
cases=(640 1920h)
[[ $# -gt 0 ]] && cases=("$@")
mkdir -p "$work"
cargo build --release --bin xsurf -q

run() {
  local name=$1
  shift
  local bag=$work/$name
  if [[ ! -f $bag/metadata.yaml ]]; then
    rm -rf "$bag"
    ./target/release/xsurf synth body -o "$bag" --zstd "$@"
  fi
  local out=$work/out-$name
  rm -rf "$out"
  /usr/bin/time -f "%e %M" -o "$work/time.txt" ./target/release/xsurf reconstruct "$bag" --params-file "$bag/params.yaml" --out "$out" --quiet > "$work/stdout.txt"
  read -r wall rss_kb < "$work/time.txt"
  python3 - "$name" "$wall" "$rss_kb" "$(nproc)" "$out/report.json" <<'PY'
import json, sys
name, wall, rss_kb, cores, report = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
r = json.load(open(report))
frames = sum(r["frames_read"].values())
print(f"{name}: {frames} frames ({len(r['cameras'])} cameras) in {wall:.2f} s wall "
      f"({frames / wall:.0f} frames/s, {frames / wall / cores:.0f} frames/s per core on {cores} cores), "
      f"peak RSS {rss_kb / 1024:.0f} MiB; study: 792 s")
print("  stages (s):", {k: round(v, 3) for k, v in r["timings_s"].items()})
print(f"  points {r['merged_points']}, triangles {r['merged_triangles']}")
PY
}

for c in "${cases[@]}"; do
  case $c in
    640) run body-640x480 --size 640x480 --speed 0.124 ;;
    1920h) run body-1920x1200-h --size 1920x1200 --speed 0.452 --horizontal cam2 ;;
    *) echo "unknown case $c (640 or 1920h)" >&2; exit 2 ;;
  esac
done
