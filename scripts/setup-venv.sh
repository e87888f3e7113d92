#!/usr/bin/env bash
# Installs the independent checkers the tests use, each from its own registry:
#  - .venv: rosbags, mcap-ros2-support, trimesh, cyclonedds, pydicom (PyPI);
#  - tests/gltf/node_modules: the Khronos glTF validator (npm);
#  - .venv/bin/vrml_check: a VRML 2.0 reader built on Coin3D (Debian's libcoin-dev);
#  - Orthanc, dcmtk and dicom3tools (Debian's orthanc, dcmtk, dicom3tools): a PACS, its DICOM peers
#    and a validator for the PACS tests.
# Idempotent: each part is redone only when its inputs change.
set -euo pipefail
cd "$(dirname "$0")/.."
# Debian puts Orthanc in /usr/sbin, which a non-login shell's PATH may lack.
export PATH="$PATH:/usr/local/sbin:/usr/sbin:/sbin"
stamp=.venv/.requirements
if ! [[ -x .venv/bin/python && -f $stamp ]] || ! cmp -s tests/requirements.txt "$stamp"; then
  python3 -m venv .venv
  .venv/bin/pip install --quiet --disable-pip-version-check -r tests/requirements.txt
  cp tests/requirements.txt "$stamp"
fi
if ! [[ -d tests/gltf/node_modules/gltf-validator ]]; then
  (cd tests/gltf && npm ci --silent --no-audit --no-fund)
fi
if ! [[ -x .venv/bin/vrml_check && .venv/bin/vrml_check -nt tests/vrml/vrml_check.cpp ]]; then
  if ! [[ -f /usr/include/Inventor/SoDB.h ]]; then
    if [[ $(id -u) -eq 0 ]]; then
      apt-get update -qq >/dev/null
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends libcoin-dev >/dev/null
    else
      echo "setup: libcoin-dev is needed for the VRML check: sudo apt-get install libcoin-dev" >&2
      exit 1
    fi
  fi
  g++ -O1 -o .venv/bin/vrml_check tests/vrml/vrml_check.cpp -lCoin
fi
# The PACS tests: Orthanc (a real PACS), dcmtk (findscu, getscu) and dicom3tools (dciodvfy).
if ! command -v Orthanc >/dev/null || ! command -v getscu >/dev/null || ! command -v dciodvfy >/dev/null; then
  if [[ $(id -u) -eq 0 ]]; then
    apt-get update -qq >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends orthanc dcmtk dicom3tools >/dev/null
    # The package starts a system Orthanc on the standard ports; the tests start their own.
    (command -v systemctl >/dev/null && systemctl stop orthanc 2>/dev/null) || service orthanc stop >/dev/null 2>&1 || true
  else
    echo "setup: orthanc, dcmtk and dicom3tools are needed for the PACS tests: sudo apt-get install orthanc dcmtk dicom3tools" >&2
    exit 1
  fi
fi
# nftables: the two-host test's packet loss on its veth link (this kernel has no netem).
if ! command -v nft >/dev/null; then
  if [[ $(id -u) -eq 0 ]]; then
    apt-get update -qq >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends nftables >/dev/null
  else
    echo "setup: nftables is needed for the two-host test: sudo apt-get install nftables" >&2
    exit 1
  fi
fi
