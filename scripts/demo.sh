#!/usr/bin/env bash
# The main job, end to end, on the built-in synthetic sample (no data needed):
# set up ./.venv, write the sample database, splice every locomotion x action pair with
# all three methods into out/spliced.h5, and describe the result.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup_env.sh
mkdir -p out
torchsplice sample -o out/sample.h5 --force
torchsplice splice-all out/sample.h5 -o out/spliced.h5 --method splice,naive,cpmc --force --restart
torchsplice info out/spliced.h5 | head -n 12
echo "..."
echo "output: $(pwd)/out/spliced.h5 (read it with torchsplice.data.MotionDataset, or export a clip:"
echo "  .venv/bin/torchsplice export out/spliced.h5 walk_curve+carry_box -o out/walk_curve+carry_box.bvh)"
