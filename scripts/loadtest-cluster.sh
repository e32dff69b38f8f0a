#!/usr/bin/env bash
# `dend loadtest` through HAProxy on N instances sharing a throw-away
# PostgreSQL (docs/reliability.md, "Load through HAProxy"). Not part of the
# test command: a measurement.
#
#   scripts/loadtest-cluster.sh INSTANCES [loadtest args...]
#   e.g. scripts/loadtest-cluster.sh 2 --sessions 40 --drags 500
#
# DEND_BIN: the dend binary (default target/release/dend).
set -euo pipefail
cd "$(dirname "$0")/.."
n="${1:?instances}"; shift
bin="${DEND_BIN:-${CARGO_TARGET_DIR:-target}/release/dend}"
tmp="$(mktemp -d)"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  bash scripts/pg-temp.sh stop "$tmp/pg" || true
  rm -rf "$tmp"
}
trap cleanup EXIT
port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
url="$(bash scripts/pg-temp.sh start "$tmp/pg" "$(port)")"
servers=""
for k in $(seq 1 "$n"); do
  p="$(port)"
  "$bin" serve --addr "127.0.0.1:$p" --store "$url" --instance-id "dend$k" >"$tmp/dend$k.log" 2>&1 &
  pids+=("$!")
  servers="$servers    server dend$k 127.0.0.1:$p check
"
  until curl -sf "http://127.0.0.1:$p/healthz/ready" >/dev/null; do sleep 0.2; done
done
lb="$(port)"
# the rules of docker/haproxy.cfg
cat >"$tmp/haproxy.cfg" <<EOF
global
    maxconn 4096
defaults
    mode http
    timeout connect 2s
    timeout client 60s
    timeout server 120s
    timeout tunnel 1h
    retries 2
    option redispatch 1
frontend dend
    bind 127.0.0.1:$lb
    default_backend dend
backend dend
    balance uri path-only depth 3
    hash-type consistent
    option httpchk GET /healthz/ready
    http-check expect status 200
    default-server inter 1s fall 2 rise 2
$servers
EOF
haproxy -db -f "$tmp/haproxy.cfg" >"$tmp/haproxy.log" 2>&1 &
pids+=("$!")
until curl -sf "http://127.0.0.1:$lb/healthz" >/dev/null; do sleep 0.2; done
echo "== $n instance(s) behind HAProxy"
"$bin" loadtest --url "http://127.0.0.1:$lb" "$@"
