#!/usr/bin/env bash
# Records every topic while a bag is played over DDS, and kills the recorder with SIGKILL
# halfway through the playback; prints the exit codes ("exits PLAY RECORD").
# Run it inside ../shared/tools/netns-run (tests/dds.rs does).
# usage: record_kill.sh BIN_DIR SRC_BAG REC_DIR LOG_DIR
set -u
bin=$1 src=$2 rec=$3 logs=$4
mkdir -p "$logs"
export ROS_LOCALHOST_ONLY=1
"$bin/xsurf" bag record -o "$rec" --all >"$logs/record.log" 2>&1 &
rpid=$!
sleep 1
# The pyramid scan lasts 2.8 s; at half speed after a 2 s discovery delay it plays from 2 s to
# 7.5 s, so the kill at 5 s falls in the middle of the scan.
"$bin/xsurf" bag play "$src" --delay 2 --rate 0.5 >"$logs/play.log" 2>&1 &
ppid=$!
sleep 5
kill -KILL $rpid
wait $rpid
rcode=$?
wait $ppid
echo "exits $? $rcode"
