#!/usr/bin/env bash
# Browser tests of the web client (web/tests/browser.test.mjs, then
# web/tests/tools.test.mjs for the posing tools, then
# web/tests/editor.test.mjs for the first minutes of a new user, then
# web/tests/feline.test.mjs for a person's drag of a 50k-vertex character, then
# web/tests/morph.test.mjs for the morph-target GLB in three.js's
# GLTFLoader, then web/tests/texture.test.mjs for textured glTF uploads,
# web/tests/artist.test.mjs for an artist's session at 1280x720,
# web/tests/uploads.test.mjs for drag-and-drop, warnings and errors,
# web/tests/rig.test.mjs for the skeleton outliner and the skeleton exports
# in three.js's GLTFLoader,
# then the JavaScript client package's (clients/js: types, packing, the
# HTTP routes, its three.js example in Chromium, reconnection):
# installs what it needs if missing (Debian's chromium,
# node/npm, and from npm playwright-core, the glTF validator and three),
# builds `dend`, and runs the test against the real `dend serve`.
# Idempotent. Under CI=true a failed install is a failure; otherwise the test
# is skipped with a message. Screenshots: web/test-artifacts/.
# `--install-only` installs and stops (for .ci/run's set-up step).
set -euo pipefail
cd "$(dirname "$0")/.."

skip_or_fail() {
  if [ "${CI:-}" = "true" ]; then
    echo "test-web: $1" >&2
    exit 1
  fi
  echo "test-web: skipping: $1" >&2
  exit 0
}

apt_install() {
  command -v apt-get >/dev/null || return 1
  local sudo=""
  [ "$(id -u)" = 0 ] || sudo="sudo -n"
  $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "$@" >/dev/null
}

CHROMIUM="${CHROMIUM:-/usr/bin/chromium}"
if [ ! -x "$CHROMIUM" ] || ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  # node and npm usually come with the machine (nodesource's nodejs bundles
  # npm and conflicts with Debian's npm package): only add them when missing.
  pkgs="chromium chromium-driver"
  command -v node >/dev/null || pkgs="$pkgs nodejs"
  command -v npm >/dev/null || pkgs="$pkgs npm"
  apt_install $pkgs || skip_or_fail "could not install $pkgs"
fi
[ -x "$CHROMIUM" ] || skip_or_fail "no chromium at $CHROMIUM"

# web/package.json's dev dependencies: playwright-core (these tests),
# gltf-validator (the Khronos glTF validator, run by tests/it/cli_gltf.rs)
# and three (its GLTFLoader, served to the page by web/tests/morph.test.mjs)
if [ ! -f web/node_modules/playwright-core/package.json ] || [ ! -f web/node_modules/gltf-validator/package.json ] \
    || [ ! -f web/node_modules/three/package.json ]; then
  (cd web && npm ci --no-audit --no-fund --loglevel=error) || skip_or_fail "npm ci (playwright-core, gltf-validator, three) failed"
fi

# clients/js's dev dependencies: typescript (its type test), three and
# @types/three (its three.js binding and example, served to the example by
# `dend serve` at /vendor/three/), playwright-core (its browser tests)
if [ ! -f clients/js/node_modules/typescript/package.json ] || [ ! -f clients/js/node_modules/three/package.json ] \
    || [ ! -f clients/js/node_modules/playwright-core/package.json ] || [ ! -f clients/js/node_modules/@types/three/package.json ]; then
  (cd clients/js && npm ci --no-audit --no-fund --loglevel=error) || skip_or_fail "npm ci in clients/js failed"
fi

[ "${1:-}" = "--install-only" ] && exit 0

# scripts/test.sh passes the binary its `cargo test` just built (same
# features, so nothing is compiled twice); run alone, build it here
if [ -z "${DEND_BIN:-}" ] || [ ! -x "$DEND_BIN" ]; then
  cargo build --bin dend
  DEND_BIN="${CARGO_TARGET_DIR:-$(pwd)/target}/debug/dend"
fi
export CHROMIUM DEND_BIN
node web/tests/frame.test.mjs
node web/tests/browser.test.mjs
node web/tests/tools.test.mjs
node web/tests/editor.test.mjs
node web/tests/feline.test.mjs
node web/tests/morph.test.mjs
node web/tests/texture.test.mjs
node web/tests/artist.test.mjs
node web/tests/uploads.test.mjs
node web/tests/rig.test.mjs
# the JavaScript client package (clients/js): its types checked by tsc on a
# consumer file, `npm pack` and its exports map (Node, and Chromium through
# an import map), every HTTP route, the three.js example dragged with the
# mouse in Chromium, and reconnection across a SIGKILL and a SIGTERM
(
  cd clients/js
  npm run -s test:types
  npm run -s test:pack
  npm run -s test:api
  npm run -s test:browser
  npm run -s test:reconnect
)
