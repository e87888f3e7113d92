#!/usr/bin/env bash
# Runs the whole live graph from the committed launch file with `xsurf launch` (MODE separate:
# one process per node; composed: `--composed`, one process), then stops the launcher with
# SIGTERM and prints its exit code. Run it inside ../shared/tools/netns-run (tests/live.rs does).
# It stops DONE_GRACE seconds after DONE_FILE appears, or after SECONDS at most.
# usage: live_graph.sh MODE BIN_DIR LAUNCH_FILE PARAMS OUT SECONDS DONE_FILE
set -u
mode=$1 bin=$2 launch=$3 params=$4 out=$5 secs=$6 done_file=$7
mkdir -p "$out"
export ROS_LOCALHOST_ONLY=1
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
kill -TERM "$pid" 2>/dev/null
wait "$pid"
echo "exits $?"
