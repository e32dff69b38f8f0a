#!/usr/bin/env bash
# The multi-instance failover test alone (scripts/test.sh runs it with the
# rest): PostgreSQL + three `dend serve` + HAProxy on loopback ports,
# SIGKILL of the owning instance mid-drags, a PostgreSQL restart under
# load; prints the figures (docs/reliability.md). Needs haproxy and
# PostgreSQL's server binaries (.ci/run installs them with apt-get).
set -euo pipefail
cd "$(dirname "$0")/.."
export DEND_FAILOVER_REPORT="${DEND_FAILOVER_REPORT:-$(mktemp)}"
cargo test --test system failover -- --nocapture
echo "== failover figures ($DEND_FAILOVER_REPORT):"
cat "$DEND_FAILOVER_REPORT"
