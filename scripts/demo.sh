#!/usr/bin/env bash
# The main job, end to end, on the built-in synthetic sample (no data needed):
# set up ./.venv, write the sample database to out/sample.h5 and describe it.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup_env.sh
mkdir -p out
torchsplice sample -o out/sample.h5 --force
torchsplice info out/sample.h5
echo "output: $(pwd)/out/sample.h5"
