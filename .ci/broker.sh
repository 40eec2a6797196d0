#!/usr/bin/env bash
# Debian's mosquitto MQTT broker for the live-monitoring tests (tests/test_watch.py
# starts its own broker processes on loopback ports). Installs the package when
# the broker is missing; prints the version either way.
set -euo pipefail
if [ ! -x /usr/sbin/mosquitto ] && ! command -v mosquitto >/dev/null 2>&1; then
  echo "installing the MQTT broker (Debian package mosquitto)"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mosquitto >/dev/null
fi
(/usr/sbin/mosquitto -h 2>/dev/null || mosquitto -h 2>/dev/null || true) | head -n 1
