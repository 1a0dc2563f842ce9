#!/bin/bash
# issue #11 round six, fit-field per iteration (quiet): `softvk fit-field` on spot's 24
# silhouettes of setup A (`field_study write DIR va=15`), 80 iterations, before (24baecf) and
# new alternately, six rounds, at the 32³ grid of the defaults the issue was filed against and
# at today's 48³. Per iteration = (seconds at iteration 80 - seconds at iteration 20) / 60 from
# the fit's `loss.csv` (its clock, logged every 10 iterations): the steady loop, without the
# first iterations, where new builds its specialized pipelines on first use (the command's own
# "ms per iteration" includes them, and the before binary builds its kernels before the loop).
DATA=${DATA:-/tmp/spotA}
declare -A BIN=([before]=/work/bin/before-24baecf [new]=/work/bin/r6)
for grid in 32 48; do
  for r in 1 2 3 4 5 6; do
    for w in before new; do
      echo "== fit-field grid $grid round $r $w $(uptime)"
      ${BIN[$w]} fit-field --silhouettes $DATA/silhouettes --cameras $DATA/cameras.csv \
        --viewing-angle 15 --grid-res $grid --iters 80 --out /tmp/round6-field.obj 2>&1 \
        | grep -o "[0-9]* iterations in [0-9.]* s ([0-9.]* ms per iteration)"
      awk -F, '$1 == 20 { a = $5 } $1 == 80 { b = $5 } END { printf "steady: %.2f ms per iteration\n", (b - a) / 60 * 1000 }' /tmp/round6-field-report/loss.csv
    done
  done
done
echo "== done $(uptime)"
