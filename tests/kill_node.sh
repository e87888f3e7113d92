#!/usr/bin/env bash
# Runs the live graph from the committed launch file (separate processes, respawn on), kills
# /cam1/triangulator with SIGKILL in the middle of scan 1, waits for scan 1's merge, asks for a
# second scan from a Cyclone DDS peer, waits for its merge, then stops the launcher with SIGTERM
# and prints "exits CODE". Run it inside ../shared/tools/netns-run (tests/live.rs does).
# usage: kill_node.sh BIN_DIR LAUNCH_FILE PARAMS OUT FILES PYTHON KILL_AFTER_S
set -u
bin=$1 launch=$2 params=$3 out=$4 files=$5 py=$6 kill_after=$7
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
mkdir -p "$out"
export ROS_LOCALHOST_ONLY=1
"$bin/xsurf" launch "$launch" "params:=$params" >"$out/launch.log" 2>&1 &
pid=$!
wait_for() { # FILE SECONDS
  for ((i = 0; i < $2 * 10; i++)); do
    [[ -f $1 ]] && return 0
    kill -0 "$pid" 2>/dev/null || return 1
    sleep 0.1
  done
  return 1
}
sleep "$kill_after"
victim=$(pgrep -f "triangulator --ros-args -r __node:=triangulator -r __ns:=/cam1" | head -1)
echo "killing $victim"
kill -KILL "$victim"
wait_for "$files/scan_1/scan_report.json" 60 || echo "scan 1 never merged"
sleep 1
"$py" "$here/py/scan_request.py" START >"$out/request.log" 2>&1 || echo "request failed"
wait_for "$files/scan_2/scan_report.json" 60 || echo "scan 2 never merged"
sleep 0.5
kill -TERM "$pid" 2>/dev/null
wait "$pid"
echo "exits $?"
