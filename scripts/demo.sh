#!/usr/bin/env bash
# The main job, end to end, on the built-in synthetic sample (no data needed):
# set up ./.venv, write the sample database, splice every locomotion x action pair with
# all three methods into out/spliced.h5 (source clips copied in), describe the result, and
# draw a preview (locomotion, action, naive, splice side by side), an alignment plot and the
# browser viewer.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup_env.sh
mkdir -p out
torchsplice sample -o out/sample.h5 --force
torchsplice splice-all out/sample.h5 -o out/spliced.h5 --method splice,naive,cpmc --copy-sources --force --restart
torchsplice info out/spliced.h5 | head -n 12
echo "..."
# the pair where the method matters most in the sample: the jog's pelvis tips forward, the box
# carrier's back, so copying the carrier's spine bend (naive) straightens the lean the splice keeps
torchsplice render out/spliced.h5 jog carry_box jog+carry_box.naive jog+carry_box \
    --overlay jog+carry_box jog+carry_box.naive --azimuth -80 --elevation 10 --max-seconds 2 \
    -o out/preview.png --frames 6 --force
torchsplice plot-alignment out/sample.h5 --locomotion walk_curve --action carry_box -o out/alignment.png --force
torchsplice view out/spliced.h5 -o out/viewer.html --force
echo "output: $(pwd)/out/spliced.h5 (read it with torchsplice.data.MotionDataset; every clip's metrics and split in out/spliced.h5.index.csv); pictures: out/preview.png, out/alignment.png; open out/viewer.html in a browser"
echo "out/preview.png: a jog, a box-carrying walk, their naive splice, the method's splice, and the splice with the naive"
echo "  one drawn over it in grey: the splice keeps the carrier's backward lean, the naive one stands straighter"
