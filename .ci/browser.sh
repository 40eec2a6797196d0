#!/usr/bin/env bash
# Debian's Chromium and ChromeDriver for the browser test of the fleet page
# (tests/test_serve.py drives it headless through Playwright). Installs the
# packages when the browser is missing; prints the version either way.
set -euo pipefail
if ! command -v chromium >/dev/null 2>&1; then
  echo "installing Chromium (Debian packages chromium, chromium-driver)"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null
fi
chromium --version 2>/dev/null | head -n 1
