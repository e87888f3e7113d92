#!/usr/bin/env bash
# Creates .venv with the independent checkers the tests use (rosbags, mcap-ros2-support,
# trimesh, cyclonedds, pydicom). Idempotent: reinstalls only when tests/requirements.txt changes.
set -euo pipefail
cd "$(dirname "$0")/.."
stamp=.venv/.requirements
if [[ -x .venv/bin/python && -f $stamp ]] && cmp -s tests/requirements.txt "$stamp"; then
  exit 0
fi
python3 -m venv .venv
.venv/bin/pip install --quiet --disable-pip-version-check -r tests/requirements.txt
cp tests/requirements.txt "$stamp"
