#!/usr/bin/env bash
# Two hosts on one machine (issue 24, item 7): network namespaces "camera" and "processing"
# joined by a veth pair, each side rate-limited to 1 Gbit/s (tc tbf) and dropping 0.5 % of the
# packets it sends (nftables numgen; this kernel has no netem, so no delay). The camera host runs
# launch-config/camera-host.launch.yaml (C-arm pose, two cameras), the processing host
# processing-host.launch.yaml; DDS discovery and data cross the pair only (no
# ROS_LOCALHOST_ONLY; each namespace has only lo and its end of the pair). Scan 1 starts by
# itself; scan 2 is asked for by a Cyclone DDS peer on the processing host. Then SIGTERM to both
# launchers. Prints "exits CAM PROC" and the packets nftables dropped per side.
# Run it inside ../shared/tools/netns-run (tests/live.rs does): the pair lives inside it.
# usage: two_hosts.sh BIN_DIR LAUNCH_DIR PARAMS OUT FILES PYTHON
set -u
bin=$1 launch_dir=$2 params=$3 out=$4 files=$5 py=$6
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
mkdir -p "$out"
cam=xsurf-cam-$$ proc=xsurf-proc-$$
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null; done
  ip netns del "$cam" 2>/dev/null
  ip netns del "$proc" 2>/dev/null
}
trap cleanup EXIT
ip netns add "$cam" && ip netns add "$proc" || exit 1
ip link add vcam netns "$cam" type veth peer name vproc netns "$proc" || exit 1
setup() { # NS DEV ADDR
  ip -n "$1" link set lo up
  ip -n "$1" addr add "$3/24" dev "$2"
  ip -n "$1" link set "$2" up multicast on
  ip -n "$1" route add 224.0.0.0/4 dev "$2"
  ip netns exec "$1" tc qdisc add dev "$2" root tbf rate 1gbit burst 256kb latency 20ms
  printf 'table inet lossy {\n chain out {\n  type filter hook output priority 0; policy accept;\n  oifname "%s" numgen random mod 200 == 0 counter drop\n }\n}\n' "$2" |
    ip netns exec "$1" nft -f -
}
setup "$cam" vcam 10.213.0.1 || exit 1
setup "$proc" vproc 10.213.0.2 || exit 1
unset ROS_LOCALHOST_ONLY
ip netns exec "$proc" "$bin/xsurf" launch "$launch_dir/processing-host.launch.yaml" "params:=$params" >"$out/processing.log" 2>&1 &
pids+=($!)
ip netns exec "$cam" "$bin/xsurf" launch "$launch_dir/camera-host.launch.yaml" "params:=$params" >"$out/camera.log" 2>&1 &
pids+=($!)
wait_for() { # FILE SECONDS
  for ((i = 0; i < $2 * 10; i++)); do
    [[ -f $1 ]] && return 0
    sleep 0.1
  done
  return 1
}
wait_for "$files/scan_1/scan_report.json" 120 || echo "scan 1 never merged"
sleep 1
# The hospital's controller on the processing host, on its end of the pair.
printf '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="vproc"/></Interfaces></General></Domain></CycloneDDS>' >"$out/cyclone.xml"
CYCLONEDDS_URI=file://$out/cyclone.xml ip netns exec "$proc" "$py" "$here/py/scan_request.py" START >"$out/request.log" 2>&1 ||
  echo "request failed"
wait_for "$files/scan_2/scan_report.json" 120 || echo "scan 2 never merged"
sleep 0.5
# Each camera_driver's account of the scan leaves 0.3 s after END (nodes/src/tally.rs) and may
# need a repair over the lossy link; the merger writes scan_report.json again as each late one
# comes. Stop once none is missing, or after 10 s (the test then says which is missing).
for ((i = 0; i < 100; i++)); do
  grep -Eq '"frames_sent": ?null' "$files/scan_2/scan_report.json" || break
  sleep 0.1
done
kill -TERM "${pids[@]}" 2>/dev/null
wait "${pids[0]}"
pe=$?
wait "${pids[1]}"
ce=$?
pids=()
echo "exits $ce $pe"
for ns in "$cam" "$proc"; do
  echo "nftables $ns: dropped $(ip netns exec "$ns" nft list ruleset | grep -o 'packets [0-9]*' | head -1)"
  echo "tc $ns: $(ip netns exec "$ns" tc -s qdisc show | tr '\n' ' ')"
  echo "link $ns: $(ip -n "$ns" -s link show | tr '\n' ' ')"
done
