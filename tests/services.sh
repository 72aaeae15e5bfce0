#!/usr/bin/env bash
# Run a command (the test suite) with the services its tests need, then stop them.
#
#   tests/services.sh .venv/bin/python -m pytest
#
# PostgreSQL: a throwaway server (a fresh cluster in a temporary directory, reached
# through a Unix socket there, no TCP port) for the tests that run against both
# SQLite and PostgreSQL; its URL goes to the command in LLCPS_TEST_POSTGRES_URL. When
# the server binaries are missing they are installed (Debian's `postgresql`) if this
# runs as root, and the PostgreSQL tests are skipped otherwise. A URL already set in
# LLCPS_TEST_POSTGRES_URL is used as it is. The server is stopped and its directory
# removed however the command ends; the script exits with the command's status.
set -uo pipefail

log() { echo "tests/services.sh: $*" >&2; }

find_pg_bin() {
    local dir
    for dir in "$(dirname "$(readlink -f "$(command -v pg_ctl 2>/dev/null || echo /nonexistent/pg_ctl)")")" \
        $(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -rV); do
        if [ -x "$dir/initdb" ] && [ -x "$dir/pg_ctl" ] && [ -x "$dir/postgres" ] && [ -x "$dir/createdb" ]; then
            echo "$dir"
            return 0
        fi
    done
    return 1
}

install_pg() {
    [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 || return 1
    log "installing PostgreSQL (apt-get install postgresql)"
    export DEBIAN_FRONTEND=noninteractive
    { apt-get install -y -q postgresql || { apt-get update -q && apt-get install -y -q postgresql; }; } >/dev/null 2>&1
}

# as_pg CMD...: run a server command as an unprivileged user (initdb refuses root).
as_pg() {
    if [ "$(id -u)" = 0 ]; then
        if command -v runuser >/dev/null 2>&1; then
            runuser -u postgres -- "$@"
        else
            su postgres -s /bin/sh -c "$(printf '%q ' "$@")"
        fi
    else
        "$@"
    fi
}

PG_DIR=""
PG_BIN=""
stop_pg() {
    if [ -n "$PG_DIR" ]; then
        as_pg "$PG_BIN/pg_ctl" -D "$PG_DIR/data" -m immediate -w stop >/dev/null 2>&1
        rm -rf "$PG_DIR"
        PG_DIR=""
    fi
}
trap stop_pg EXIT
trap 'stop_pg; exit 130' INT
trap 'stop_pg; exit 143' TERM

start_pg() {
    PG_BIN="$(find_pg_bin)" || { install_pg && PG_BIN="$(find_pg_bin)"; } || {
        log "PostgreSQL not found (and not root to install it): the PostgreSQL tests will be skipped"
        return 1
    }
    if [ "$(id -u)" = 0 ] && ! id postgres >/dev/null 2>&1; then
        log "no 'postgres' user to run the server as: the PostgreSQL tests will be skipped"
        return 1
    fi
    PG_DIR="$(mktemp -d "${TMPDIR:-/tmp}/llcps-pg.XXXXXX")"
    chmod 755 "$PG_DIR"
    [ "$(id -u)" = 0 ] && chown postgres "$PG_DIR"
    if ! as_pg "$PG_BIN/initdb" -D "$PG_DIR/data" -U postgres --auth=trust -E UTF8 --no-sync >"$PG_DIR/initdb.log" 2>&1; then
        log "initdb failed: the PostgreSQL tests will be skipped"; cat "$PG_DIR/initdb.log" >&2; stop_pg; return 1
    fi
    local options="-k $PG_DIR -c listen_addresses= -c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=200"
    if ! as_pg "$PG_BIN/pg_ctl" -D "$PG_DIR/data" -o "$options" -l "$PG_DIR/server.log" -w -t 60 start >/dev/null; then
        log "the server did not start: the PostgreSQL tests will be skipped"; cat "$PG_DIR/server.log" >&2; stop_pg; return 1
    fi
    if ! as_pg "$PG_BIN/createdb" -h "$PG_DIR" -U postgres llcps_test; then
        log "createdb failed: the PostgreSQL tests will be skipped"; stop_pg; return 1
    fi
    export LLCPS_TEST_POSTGRES_URL="postgresql+psycopg://postgres@/llcps_test?host=$PG_DIR"
    log "PostgreSQL $("$PG_BIN/postgres" --version | awk '{print $3}') at $PG_DIR (LLCPS_TEST_POSTGRES_URL)"
}

if [ $# -eq 0 ]; then
    echo "usage: tests/services.sh COMMAND [ARG...]" >&2
    exit 2
fi
if [ -z "${LLCPS_TEST_POSTGRES_URL:-}" ]; then
    start_pg
fi
"$@"
status=$?
stop_pg
exit $status
