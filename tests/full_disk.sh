#!/usr/bin/env bash
# Runs COMMAND with the folder OUT on a tmpfs of SIZE bytes (a disk that fills up), in a private
# mount namespace; then copies what OUT holds to KEEP and prints "exit CODE".
# usage: full_disk.sh SIZE OUT KEEP COMMAND [ARGS...]
set -u
if [[ ${XSURF_FULL_DISK:-} != 1 ]]; then
  args=(-m)
  [[ $(id -u) -eq 0 ]] || args=(-r -m)
  XSURF_FULL_DISK=1 exec unshare "${args[@]}" "$0" "$@"
fi
size=$1 out=$2 keep=$3
shift 3
mkdir -p "$out" "$keep"
mount -t tmpfs -o size="$size" tmpfs "$out" || { echo "cannot mount a tmpfs on $out"; exit 97; }
"$@"
code=$?
cp -a "$out/." "$keep/"
echo "exit $code"
