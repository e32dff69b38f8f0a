#!/usr/bin/env bash
# Runs every test: the README's test command (`bash scripts/test.sh`).
# Installs the test-only tools first (idempotent), then: formatting and lint
# gates, the Rust test suite (unit, integration, CLI, server end to end),
# then the browser test of the web client.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEND_MESHES="${DEND_MESHES:-$(cd .. && pwd)/shared/meshes}"
export DEND_PYTHON="${DEND_PYTHON:-$(pwd)/.venv/bin/python}"
# a build from scratch (CI's) gains nothing from incremental compilation,
# whose caches were 7 GB of target/debug
if [ "${CI:-}" = true ]; then export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"; fi
bash scripts/setup-test-env.sh
cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
# no import cycle between files, no stale path in docs and comments
# (docs/architecture.md, "Layering")
python3 scripts/module_cycles.py
python3 scripts/stale_paths.py
# benches are compiled by clippy above; running them is `cargo bench`
# tests that cannot run here (no ../shared/meshes) record why in this file
export DEND_SKIP_LOG="$(mktemp)"
# a throw-away PostgreSQL for the store suite's PostgreSQL backend
# (DEND_TEST_POSTGRES); tests/system/failover.rs starts its own, with HAProxy
PG_TMP="$(mktemp -d)"
cleanup() { bash scripts/pg-temp.sh stop "$PG_TMP/pg" || true; rm -rf "$PG_TMP" "$DEND_SKIP_LOG"; }
trap cleanup EXIT
if [ -z "${DEND_TEST_POSTGRES:-}" ] && bash scripts/pg-temp.sh bindir >/dev/null 2>&1; then
  PG_PORT="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
  DEND_TEST_POSTGRES="$(bash scripts/pg-temp.sh start "$PG_TMP/pg" "$PG_PORT")"
  export DEND_TEST_POSTGRES
fi
# the failover test's figures (docs/reliability.md)
export DEND_FAILOVER_REPORT="${DEND_FAILOVER_REPORT:-$PG_TMP/failover.json}"
cargo test --workspace --lib --bins --tests --examples
[ -s "$DEND_FAILOVER_REPORT" ] && { echo "== failover figures:"; cat "$DEND_FAILOVER_REPORT"; }
# the Python client's tests, against a real `dend serve` (the binary cargo
# test built for the CLI tests)
export DEND_BIN="${CARGO_TARGET_DIR:-$(pwd)/target}/debug/dend"
.venv/bin/python -m pytest -q clients/python/tests
# the Blender add-on's headless test, the morph-target GLB imported
# with its named poses as shape keys, and the skeleton exports (imported,
# and applied by the add-on as an action and corrective shape keys)
# (Debian's `blender`; .ci/run installs it)
if command -v blender >/dev/null; then
  BLENDER_LOG="$(mktemp)"
  for t in test_addon test_import test_rig; do
    if ! blender -b --factory-startup --python-exit-code 1 \
        --python "clients/blender/tests/$t.py" >"$BLENDER_LOG" 2>&1; then
      cat "$BLENDER_LOG"
      exit 1
    fi
    grep -E "^(shape key|dend blender)" "$BLENDER_LOG"
  done
  rm -f "$BLENDER_LOG"
elif [ "${CI:-}" = true ]; then
  echo "blender is not installed: CI must run the add-on's test" >&2
  exit 1
else
  echo "blender not installed: the Blender add-on's and import tests did not run" >> "$DEND_SKIP_LOG"
fi
# the browser test drives the `dend` binary cargo test built for the CLI tests
DEND_BIN="${CARGO_TARGET_DIR:-$(pwd)/target}/debug/dend" bash scripts/test-web.sh
if [ -s "$DEND_SKIP_LOG" ]; then
  echo "== skipped (the properties are also tested on generated meshes):"
  sort -u "$DEND_SKIP_LOG"
else
  echo "== no test skipped"
fi
