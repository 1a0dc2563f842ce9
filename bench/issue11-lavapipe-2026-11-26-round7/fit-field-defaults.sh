#!/bin/bash
# issue #11 round seven, fit-field at its defaults in full (quiet): `softvk fit-field` on spot's
# 24 silhouettes of setup A (`field_study write DIR va=15`) with today's defaults, before
# (24baecf) and new alternately, three rounds. The before binary predates issue #16's defaults
# (48³ grid, 1 000 iterations; were 32³ and 150): both get them as options; every other default
# is the same in both (their `--help`). Per iteration = the
# command's own "N iterations in T s" (every iteration, pipelines built on first use included),
# and the median of the 10-iteration blocks of its `loss.csv` clock: on this machine a fit's
# speed switches between two levels for stretches of tens of iterations (both binaries).
DATA=${DATA:-/tmp/spotA}
declare -A BIN=([before]=/work/bin/before-24baecf [new]=/work/bin/r7)
for r in 1 2 3; do
  for w in before new; do
    echo "== fit-field defaults round $r $w $(uptime)"
    ${BIN[$w]} fit-field --silhouettes $DATA/silhouettes --cameras $DATA/cameras.csv \
      --viewing-angle 15 --grid-res 48 --iters 1000 --quiet --out /tmp/round7-defaults.obj 2>&1 \
      | grep -o "[0-9]* iterations in [0-9.]* s ([0-9.]* ms per iteration)"
    awk -F, 'NR > 1 { if (p != "") print ($5 - p) * 100; p = $5 }' /tmp/round7-defaults-report/loss.csv \
      | sort -n | awk '{ v[NR] = $1 } END { printf "median 10-iteration block: %.2f ms per iteration (%d blocks, %.1f to %.1f)\n", (NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2), NR, v[1], v[NR] }'
  done
done
echo "== done $(uptime)"
