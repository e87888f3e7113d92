#!/usr/bin/env bash
# The algorithm crate must not depend on middleware, bag storage or an async runtime
# (as rerun checks its own layering in CI).
set -euo pipefail
cd "$(dirname "$0")/.."
tree=$(cargo tree -p xsurf-core -e normal,build --prefix none --format '{p}')
bad=$(grep -E '^(ros2-client|rustdds|mcap|tokio|smol|async-std|async-io|futures|mio) ' <<<"$tree" || true)
if [[ -n $bad ]]; then
  echo "xsurf-core depends on forbidden crates:" >&2
  echo "$bad" >&2
  exit 1
fi
echo "xsurf-core: $(wc -l <<<"$tree") crates, none forbidden"
