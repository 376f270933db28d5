#!/usr/bin/env bash
# Design the speckle pattern for a target moving at 200 mm/s, 1 ms exposure, 0.05 mm/px
# (W = 4 px), with a print-ready export at 600 DPI.
#   bash examples/design.sh [OUTDIR]
# Small search so that it runs in under a minute; drop the last line of options for the
# full search (a 5x3x3 grid, 20 refinement campaigns, 8 confirmation realisations).
set -euo pipefail
out=${1:-design}
dicblur design --velocity 200mm/s --exposure 1ms --scale 0.05mm/px --noise 2 --subset 31 \
    --print-size 100x100 --dpi 600 -o "$out" \
    --image-size 128 --grid 2x1x2 --max-refine 2 --confirm 2 --realisations 1
