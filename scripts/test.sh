#!/usr/bin/env bash
# Runs every test: the README's test command (`bash scripts/test.sh`).
set -euo pipefail
cd "$(dirname "$0")/.."
export DEND_MESHES="${DEND_MESHES:-$(cd .. && pwd)/shared/meshes}"
export DEND_PYTHON="${DEND_PYTHON:-$(pwd)/.venv/bin/python}"
bash scripts/setup-test-env.sh
cargo test --all-targets
