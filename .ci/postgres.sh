#!/usr/bin/env bash
# Start or stop a private PostgreSQL server on 127.0.0.1 for the store tests.
#   source .ci/postgres.sh start   -> exports CONDMON_TEST_POSTGRES_URL
#   .ci/postgres.sh stop
# Installs Debian's postgresql package when no server binaries are present.
set -euo pipefail
PGPORT="${CONDMON_PGPORT:-55432}"
PGDATA="${CONDMON_PGDATA:-/tmp/condmon-pg-$PGPORT}"

pgbin() {
  ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1
}

case "${1:-}" in
  start)
    if [ -z "$(pgbin)" ]; then
      echo "installing PostgreSQL (Debian package)"
      apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql >/dev/null
    fi
    BIN="$(pgbin)"
    id postgres >/dev/null 2>&1 || useradd --system --no-create-home postgres
    rm -rf "$PGDATA"
    mkdir -p "$PGDATA" && chown postgres "$PGDATA" && chmod 700 "$PGDATA"
    runuser -u postgres -- "$BIN/initdb" -D "$PGDATA" -A trust -U postgres >/dev/null
    runuser -u postgres -- "$BIN/pg_ctl" -D "$PGDATA" -l "$PGDATA/server.log" -w \
      -o "-p $PGPORT -k $PGDATA -c listen_addresses=127.0.0.1 -c fsync=off" start >/dev/null
    export CONDMON_TEST_POSTGRES_URL="postgresql://postgres@127.0.0.1:$PGPORT/postgres"
    echo "PostgreSQL running at $CONDMON_TEST_POSTGRES_URL"
    ;;
  stop)
    BIN="$(pgbin)"
    if [ -n "$BIN" ] && [ -d "$PGDATA" ]; then
      runuser -u postgres -- "$BIN/pg_ctl" -D "$PGDATA" -m fast -w stop >/dev/null || true
      rm -rf "$PGDATA"
    fi
    ;;
  *)
    echo "usage: $0 start|stop" >&2
    exit 2
    ;;
esac
