#!/usr/bin/env bash
# Set up ./.venv and run the test suite (extra arguments go to pytest).
#   bash scripts/test.sh          the quick suite: every test but those marked slow (a few minutes)
#   bash scripts/test.sh --all    every test; CI (CI=true) always runs every test
# Real-data tests read ../shared/mocap (or $TORCHSPLICE_MOCAP) and skip, saying why, without it
# (under CI its absence fails them instead).
set -euo pipefail
cd "$(dirname "$0")/.."
all=0
if [ "${1:-}" = "--all" ]; then all=1; shift; fi
case "${CI:-}" in true|1|yes) all=1 ;; esac
TORCHSPLICE_EXTRAS="test,ray" . scripts/setup_env.sh
if [ "$all" = 0 ]; then
  echo "test: the quick suite (tests marked slow left out; --all runs them too)" >&2
  set -- -m "not slow" "$@"
fi
exec python -m pytest "$@"
