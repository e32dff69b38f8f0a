#!/usr/bin/env bash
# Installs the test-only tools a fresh machine lacks. Idempotent.
# - a Python virtual environment (.venv) with libigl, numpy and scipy: the
#   external oracle for the discrete operators and the ARAP baseline;
#   pytest and the Python client (clients/python, installed editable, so the
#   tests run the checked-out source) for its tests.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c "import igl, numpy, scipy, jsonschema" 2>/dev/null; then
  python3 -m venv .venv
  .venv/bin/pip install --quiet --disable-pip-version-check libigl numpy scipy jsonschema
fi
if ! .venv/bin/python -c "import dend_client, pytest, httpx, websockets" 2>/dev/null; then
  .venv/bin/pip install --quiet --disable-pip-version-check pytest -e ./clients/python
fi
