#!/usr/bin/env bash
# Reproduce the evaluation on the real Bandai Namco ground-truth sets:
# import the clips, splice every style's straight walk onto every normal-style locomotion with
# all three methods, and write out/ground_truth/report.md (numbers quoted in docs/pictures.md).
# Real data: ../shared/mocap (or $TORCHSPLICE_MOCAP).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup_env.sh
mocap="${TORCHSPLICE_MOCAP:-../shared/mocap}"
out=out/ground_truth
mkdir -p "$out"
torchsplice import "$mocap/bandai_namco_research_motiondataset" --spec bandai_namco -o "$out/bandai.h5" --force -q
torchsplice splice-all "$out/bandai.h5" -o "$out/spliced.h5" --force --restart --force-locomotion \
    --locomotions 'label:style=normal' --locomotions 'label:content=walk-*,label:content=run,label:content=dash' \
    --actions 'label:content=walk' --method splice,naive,cpmc
torchsplice evaluate "$out/spliced.h5" -o "$out/report.md" --force
