#!/usr/bin/env bash
# Calibrate, predict, plan: from a speckle pattern to the exposure to use.
#   bash examples/walkthrough.sh [OUTDIR]
# Small sizes so that it runs in seconds; for a real calibration drop --size and --blur
# (the paper's sweep: a 512x512 pattern, W = 0.1..10 px in 0.1 px steps).
set -euo pipefail
out=${1:-walkthrough}
mkdir -p "$out"

# 1. a pattern (or use your own image file)
dicblur pattern generate "$out/pattern.tif" --size 128x128 --speckle-size 4 --density 0.5 \
    --softness 1 --seed 1
dicblur pattern metrics "$out/pattern.tif" --subset 21

# 2. the blur sweep on it and the model fits (model.json, results, figures)
dicblur calibrate "$out/pattern.tif" --noise 2 --subset 21 --blur 0:4:1 --serial -q \
    -o "$out/calibration"

# 3. predict u_e for a target moving at 120 mm/s, 1 ms exposure, 0.05 mm per px (W = 2.4 px)
dicblur predict "$out/calibration/model.json" --velocity 120mm/s --exposure 1ms \
    --scale 0.05mm/px

# 4. the longest exposure that keeps u_e under 0.02 px, with its figure
dicblur plan "$out/calibration/model.json" --velocity 120mm/s --scale 0.05mm/px \
    --target 0.02px --noise 2 --plot "$out/plan.png"
