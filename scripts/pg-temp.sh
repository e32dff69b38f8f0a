#!/usr/bin/env bash
# A throw-away PostgreSQL for the tests: Debian's server binaries, its own
# data directory under DIR, listening on 127.0.0.1:PORT only, trust
# authentication for the role `dend` (a superuser of this cluster only).
# As root it runs as the unprivileged `postgres` user (or `nobody`), since
# PostgreSQL refuses to run as root.
#
#   scripts/pg-temp.sh start DIR PORT   # prints the URL once it accepts connections
#   scripts/pg-temp.sh stop DIR
#   scripts/pg-temp.sh bindir           # where initdb/postgres are (exit 1: none)
set -euo pipefail

bindir() {
  if [ -n "${DEND_PG_BINDIR:-}" ] && [ -x "$DEND_PG_BINDIR/postgres" ]; then
    echo "$DEND_PG_BINDIR"; return 0
  fi
  local d
  for d in $(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V -r); do
    if [ -x "$d/postgres" ] && [ -x "$d/initdb" ]; then echo "$d"; return 0; fi
  done
  if command -v postgres >/dev/null && command -v initdb >/dev/null; then
    dirname "$(command -v postgres)"; return 0
  fi
  return 1
}

# run a command as the unprivileged server user when we are root
as_pg() {
  if [ "$(id -u)" = 0 ]; then
    local user=postgres
    getent passwd postgres >/dev/null || user=nobody
    runuser -u "$user" -- "$@"
  else
    "$@"
  fi
}

pg_user() {
  if [ "$(id -u)" = 0 ]; then
    if getent passwd postgres >/dev/null; then echo postgres; else echo nobody; fi
  else
    id -un
  fi
}

cmd="${1:-}"
case "$cmd" in
  bindir) bindir ;;
  start)
    dir="$2"; port="$3"
    bin="$(bindir)" || { echo "no PostgreSQL server binaries (apt-get install postgresql)" >&2; exit 1; }
    mkdir -p "$dir"
    chmod 755 "$dir"
    # the server user must reach DIR: a mktemp -d parent is root-only
    [ "$(id -u)" = 0 ] && chmod a+x "$(dirname "$dir")"
    user="$(pg_user)"
    if [ ! -f "$dir/data/PG_VERSION" ]; then
      mkdir -p "$dir/data" "$dir/sock"
      chown "$user" "$dir/data" "$dir/sock" 2>/dev/null || true
      chmod 700 "$dir/data"
      as_pg "$bin/initdb" -D "$dir/data" -U dend -A trust --no-sync >"$dir/initdb.log" 2>&1 \
        || { cat "$dir/initdb.log" >&2; exit 1; }
    fi
    touch "$dir/server.log"; chown "$user" "$dir/server.log" 2>/dev/null || true
    as_pg "$bin/pg_ctl" -D "$dir/data" -l "$dir/server.log" -w -t 60 \
      -o "-p $port -k $dir/sock -c listen_addresses=127.0.0.1 -c max_connections=200" start >/dev/null \
      || { cat "$dir/server.log" >&2; exit 1; }
    echo "postgres://dend@127.0.0.1:$port/postgres"
    ;;
  stop)
    dir="$2"
    bin="$(bindir)" || exit 0
    [ -f "$dir/data/postmaster.pid" ] && as_pg "$bin/pg_ctl" -D "$dir/data" -m fast -w stop >/dev/null 2>&1 || true
    ;;
  *) echo "usage: $0 start DIR PORT | stop DIR | bindir" >&2; exit 2 ;;
esac
