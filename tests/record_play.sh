#!/usr/bin/env bash
# Records every topic while a bag is played over DDS; prints the exit codes.
# Run it inside ../shared/tools/netns-run (tests/dds.rs does).
# usage: record_play.sh BIN_DIR SRC_BAG REC_DIR LOG_DIR
# Environment: PLAYS (default 1) plays the bag that many times, one after the other;
# RECORD_ARGS (default --all) are the recorder's options.
set -u
bin=$1 src=$2 rec=$3 logs=$4
mkdir -p "$logs"
export ROS_LOCALHOST_ONLY=1
# shellcheck disable=SC2086 # RECORD_ARGS is a list of options
"$bin/xsurf" bag record -o "$rec" ${RECORD_ARGS:---all} >"$logs/record.log" 2>&1 &
rpid=$!
sleep 1
pcode=0
for ((k = 0; k < ${PLAYS:-1}; k++)); do
  "$bin/xsurf" bag play "$src" --delay 3 >>"$logs/play.log" 2>&1 || pcode=$?
done
sleep 2
kill -TERM $rpid
wait $rpid
echo "exits $pcode $?"
