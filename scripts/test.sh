#!/usr/bin/env bash
# Set up ./.venv and run the test suite (extra arguments go to pytest).
# Real-data tests read ../shared/mocap (or $TORCHSPLICE_MOCAP) and skip, saying why, without it.
set -euo pipefail
cd "$(dirname "$0")/.."
TORCHSPLICE_EXTRAS="test,ray" . scripts/setup_env.sh
exec python -m pytest "$@"
