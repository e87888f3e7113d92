#!/usr/bin/env bash
# Runs the whole live graph for SECONDS, then stops it with SIGTERM and prints the exit codes.
# MODE composed: one `xsurf compose` process; separate: one process per node.
# Run it inside ../shared/tools/netns-run (tests/live.rs does).
# It stops the graph DONE_GRACE seconds after DONE_FILE appears, or after SECONDS at most.
# usage: live_graph.sh MODE BIN_DIR PARAMS OUT SECONDS DONE_FILE
set -u
mode=$1 bin=$2 params=$3 out=$4 secs=$5 done_file=$6
mkdir -p "$out"
export ROS_LOCALHOST_ONLY=1
pids=()
if [[ $mode == composed ]]; then
  "$bin/xsurf" compose /c_arm_pose /cam1/camera_driver /cam2/camera_driver /cam1/edge_detector /cam2/edge_detector \
    /cam1/triangulator /cam2/triangulator /cam1/mesher /cam2/mesher /merger \
    --ros-args --params-file "$params" >"$out/compose.log" 2>&1 &
  pids+=($!)
else
  for cam in cam1 cam2; do
    for n in camera_driver edge_detector triangulator mesher; do
      "$bin/$n" --ros-args -r __ns:=/$cam --params-file "$params" >"$out/${cam}_$n.log" 2>&1 &
      pids+=($!)
    done
  done
  "$bin/merger" --ros-args --params-file "$params" >"$out/merger.log" 2>&1 &
  pids+=($!)
  sleep 3 # let the graph match before the C-arm starts moving
  "$bin/c_arm_pose" --ros-args --params-file "$params" >"$out/c_arm_pose.log" 2>&1 &
  pids+=($!)
fi
for ((i = 0; i < secs * 10; i++)); do
  [[ -f $done_file ]] && break
  sleep 0.1
done
sleep 0.5
kill -TERM "${pids[@]}" 2>/dev/null
codes=()
for p in "${pids[@]}"; do
  wait "$p"
  codes+=($?)
done
echo "exits ${codes[*]}"
