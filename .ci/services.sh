#!/usr/bin/env bash
# System packages and services the test suite needs; `make test` runs this first.
# As root (CI) it installs what is missing; otherwise it only says what is missing,
# and the tests that need it are skipped with the reason.
set -euo pipefail

# Headless Chromium and its WebDriver (Debian's, matching versions): the browser test
# opens the HTML experiment report in them.
if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "services: installing chromium and chromium-driver" >&2
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null
  else
    echo "services: chromium or chromedriver missing and not root: the browser test will be skipped" >&2
  fi
fi
