#!/usr/bin/env bash
# Runs the whole live graph from the committed launch file with `xsurf launch` (MODE separate:
# one process per node; composed: `--composed`, one process), then stops the launcher with
# SIGTERM and prints its exit code. Run it inside ../shared/tools/netns-run (tests/live.rs does).
# It stops DONE_GRACE seconds after DONE_FILE appears, or after SECONDS at most.
# usage: live_graph.sh MODE BIN_DIR LAUNCH_FILE PARAMS OUT SECONDS DONE_FILE
#        (environment: ORTHANC_CONFIG, ORTHANC_DICOM_PORT, ORTHANC_HTTP_PORT, QUEUE_DIR, FETCH_DIR)
set -u
mode=$1 bin=$2 launch=$3 params=$4 out=$5 secs=$6 done_file=$7
mkdir -p "$out"
export ROS_LOCALHOST_ONLY=1
# With ORTHANC_CONFIG (an Orthanc JSON: DICOM port ORTHANC_DICOM_PORT, REST port
# ORTHANC_HTTP_PORT), a PACS runs in this namespace during the scan; after the scan, once the
# merger's queue (QUEUE_DIR) is empty, every instance it holds is fetched into FETCH_DIR.
orthanc=
if [[ -n ${ORTHANC_CONFIG:-} ]]; then
  Orthanc "$ORTHANC_CONFIG" >"$out/orthanc.log" 2>&1 &
  orthanc=$!
  for ((i = 0; i < 600; i++)); do
    (exec 3<>"/dev/tcp/127.0.0.1/$ORTHANC_DICOM_PORT") 2>/dev/null && break
    sleep 0.1
  done
fi
flag=()
[[ $mode == composed ]] && flag=(--composed)
"$bin/xsurf" launch "$launch" "${flag[@]}" "params:=$params" >"$out/launch.log" 2>&1 &
pid=$!
for ((i = 0; i < secs * 10; i++)); do
  [[ -f $done_file ]] && break
  kill -0 "$pid" 2>/dev/null || break
  sleep 0.1
done
sleep 0.5
if [[ -n $orthanc ]]; then
  for ((i = 0; i < 300; i++)); do
    [[ -z $(find "$QUEUE_DIR" -mindepth 1 -maxdepth 1 -type d ! -name '.*' 2>/dev/null) && -d $QUEUE_DIR ]] && break
    sleep 0.1
  done
fi
kill -TERM "$pid" 2>/dev/null
wait "$pid"
echo "exits $?"
if [[ -n $orthanc ]]; then
  mkdir -p "$FETCH_DIR"
  python3 - "$ORTHANC_HTTP_PORT" "$FETCH_DIR" <<'PY'
import json, sys, urllib.request
port, out = sys.argv[1], sys.argv[2]
base = f"http://127.0.0.1:{port}"
for i in json.load(urllib.request.urlopen(f"{base}/instances")):
    with open(f"{out}/{i}.dcm", "wb") as f:
        f.write(urllib.request.urlopen(f"{base}/instances/{i}/file").read())
PY
  kill -TERM "$orthanc"
  wait "$orthanc"
fi
