#!/usr/bin/env bash
# Benchmark (not a test) of a full-body surface sent to a PACS (issue 21): the surface of a
# full-body scan (`xsurf synth body` at 640x480, 390 frames a camera, reconstructed with its
# radiograph: surface.dcm and xray.dcm) stored RUNS times in a local Orthanc (started here on
# loopback ports with a temporary storage, instances overwritten so each store is whole) by
# `xsurf pacs send`, and by dcmtk's storescu in the same run (the reference). Times are of the
# whole command (a process, one association, the C-STORE and its answer). Writing surface.dcm:
# `cargo bench -p xsurf-formats --bench dicom_surface`.
# usage: bash scripts/bench-pacs.sh [RUNS]
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-5}
cargo build --release -p xsurf-nodes --bins >/dev/null
bin=$PWD/target/release
work=$(mktemp -d /tmp/xsurf-bench-pacs.XXXXXX)
echo "== a full-body scan at 640x480, reconstructed ($work)" >&2
"$bin/xsurf" synth body -o "$work/bag" --size 640x480 --speed 0.124 >/dev/null
"$bin/xsurf" reconstruct "$work/bag" --xray "$work/bag/xray.dcm" --out "$work/rec" --quiet >/dev/null || true
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
http=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
cat >"$work/orthanc.json" <<JSON
{"Name": "xsurf-bench", "StorageDirectory": "$work/db", "IndexDirectory": "$work/db", "HttpPort": $http,
 "RemoteAccessAllowed": false, "AuthenticationEnabled": false, "DicomAet": "ORTHANC", "DicomPort": $port,
 "UnknownSopClassAccepted": false, "OverwriteInstances": true, "Plugins": []}
JSON
Orthanc "$work/orthanc.json" >"$work/orthanc.log" 2>&1 &
orthanc=$!
trap 'kill -TERM $orthanc 2>/dev/null; wait $orthanc 2>/dev/null' EXIT
for ((i = 0; i < 600; i++)); do
  (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null && break
  sleep 0.1
done
python3 - "$bin/xsurf" "$work/rec" "ORTHANC@127.0.0.1:$port" "$port" "$runs" <<'PY'
import json, os, statistics, subprocess, sys, time
xsurf, rec, addr, port, runs = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5])
report = json.load(open(f"{rec}/report.json"))
def timed(cmd):
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0
out = {"merged_points": report["merged_points"], "merged_triangles": report["merged_triangles"]}
for name in ["surface.dcm", "xray.dcm"]:
    f = f"{rec}/{name}"
    ours = [timed([xsurf, "pacs", "send", f, addr]) for _ in range(runs)]
    dcmtk = [timed(["storescu", "-R", "-aet", "XSURF", "-aec", "ORTHANC", "127.0.0.1", port, f]) for _ in range(runs)]
    out[name] = {
        "bytes": os.path.getsize(f),
        "xsurf_pacs_send_s": {"median": statistics.median(ours), "min": min(ours), "max": max(ours)},
        "storescu_s": {"median": statistics.median(dcmtk), "min": min(dcmtk), "max": max(dcmtk)},
        "ratio_median": statistics.median(ours) / statistics.median(dcmtk),
    }
print(json.dumps(out, indent=1))
PY
