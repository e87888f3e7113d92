#!/usr/bin/env bash
# The whole test suite, as CI runs it on a fresh clone: set-up, format, lints, the
# forbidden-dependency check, and every test (release build: the synthetic scanner renders
# real images).
set -euo pipefail
cd "$(dirname "$0")/.."
# Debian puts Orthanc in /usr/sbin, which a non-login shell's PATH may lack.
export PATH="$PATH:/usr/local/sbin:/usr/sbin:/sbin"
export CARGO_TERM_COLOR=never
echo "== set-up: Python checkers"
bash scripts/setup-venv.sh
echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== forbidden dependencies of the algorithm crate"
bash scripts/check-deps.sh
echo "== cargo clippy"
cargo clippy --workspace --all-targets --release -- -D warnings
echo "== cargo clippy, the V4L2 source (cargo feature v4l2)"
cargo clippy -p xsurf-nodes --features v4l2 --lib --release -- -D warnings
echo "== cargo test"
# Every test binary runs (--no-fail-fast), so one failure does not hide the others; the exit
# status is the suite's.
status=0
XSURF_REQUIRE_CHECKERS=1 cargo test --workspace --release --no-fail-fast 2>&1 | tee target/test-output.txt || status=1
echo "== cargo test, the V4L2 source (no camera here: the conversions and a missing device)"
cargo test -p xsurf-nodes --features v4l2 --lib --release -- v4l2 2>&1 | tee -a target/test-output.txt || status=1
# One closing line summing every test binary.
awk '/^test result:/ {p += $4; f += $6} END {printf "%d passed, %d failed\n", p, f}' target/test-output.txt
exit $status
