#!/usr/bin/env bash
# Records every topic while a bag is played over DDS; prints the exit codes.
# Run it inside ../shared/tools/netns-run (tests/dds.rs does).
# usage: record_play.sh BIN_DIR SRC_BAG REC_DIR LOG_DIR
set -u
bin=$1 src=$2 rec=$3 logs=$4
mkdir -p "$logs"
export ROS_LOCALHOST_ONLY=1
"$bin/xsurf" bag record -o "$rec" --all >"$logs/record.log" 2>&1 &
rpid=$!
sleep 1
"$bin/xsurf" bag play "$src" --delay 3 >"$logs/play.log" 2>&1
pcode=$?
sleep 2
kill -TERM $rpid
wait $rpid
echo "exits $pcode $?"
