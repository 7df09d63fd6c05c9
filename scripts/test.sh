#!/usr/bin/env bash
# Set up ./.venv and run the test suite (extra arguments go to pytest).
# Real-data tests read ../shared/mocap (or $TORCHSPLICE_MOCAP) and skip, saying why, without it.
# The viewer's browser tests need Debian's chromium and chromium-driver: installed here with
# apt-get when missing and running as root (set TORCHSPLICE_NO_APT=1 not to); without them those
# tests skip, saying why, except under CI=true, where they fail.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! { command -v chromium >/dev/null && command -v chromedriver >/dev/null; } \
    && [ "$(id -u)" = 0 ] && [ -z "${TORCHSPLICE_NO_APT:-}" ] && command -v apt-get >/dev/null; then
  echo "setup: installing chromium and chromium-driver for the browser tests" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null
  apt-get install -y -qq --no-install-recommends chromium chromium-driver >/dev/null
fi
TORCHSPLICE_EXTRAS="test,ray" . scripts/setup_env.sh
exec python -m pytest "$@"
