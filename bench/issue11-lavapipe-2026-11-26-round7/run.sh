#!/bin/bash
# One quiet run: issue #11 round seven. Binaries, each `cargo build --release` of the commit named:
#   before = 24baecf (the commit before issue #11's work), r6 = 4c353e3 (round six's kernels;
#   main's a78f8d3 runs the same), new = this round's final commit.
# spot-256 forward+backward alternately (order rotated per round), nine rounds; fit-120 once
# each; then `softvk fit-field` (the command line: the before binary has no `fit-field` bench
# scene) on spot's 24 silhouettes of setup A (`field_study write DIR va=15`), 80 iterations, at
# the 32³ grid of the defaults the issue was filed against and at today's 48³, six rounds with
# the order rotated: per iteration = (seconds at iteration 80 - seconds at iteration 20) / 60
# from the fit's `loss.csv` clock (the steady loop; the command's own "ms per iteration" line,
# printed beside it, includes the first iterations, where new builds its pipelines on first use).
export SOFTVK_ASSETS=${SOFTVK_ASSETS:-/work/shared/assets}
declare -A BIN=([before]=/work/bin/before-24baecf [r6]=/work/bin/r6 [new]=/work/bin/r7)
DATA=${DATA:-/tmp/spotA}
OUT=${OUT:-$(dirname "$0")}; mkdir -p "$OUT" && cd "$OUT" && rm -f spot-256-*.json fit-120-*.json
names=(before r6 new)
for r in 1 2 3 4 5 6 7 8 9; do
  for i in 0 1 2; do
    w=${names[$(( (i + r) % 3 ))]}
    echo "== spot-256 $w round $r $(uptime)"
    ${BIN[$w]} bench --scene spot-256 --tile 8 --no-brute --repeat 9 --json spot-256-$w-$r.json 2>&1 | grep "forward+backward:"
  done
done
for w in before r6 new; do
  echo "== fit-120 $w $(uptime)"
  ${BIN[$w]} bench --scene fit-120 --repeat 3 --json fit-120-$w.json 2>&1 | grep -v "^$" | grep -v '^\[\|^  {\|^\]'
done
for grid in 32 48; do
  for r in 1 2 3 4 5 6; do
    for i in 0 1 2; do
      w=${names[$(( (i + r) % 3 ))]}
      echo "== fit-field grid $grid round $r $w $(uptime)"
      ${BIN[$w]} fit-field --silhouettes $DATA/silhouettes --cameras $DATA/cameras.csv \
        --viewing-angle 15 --grid-res $grid --iters 80 --quiet --out /tmp/round7-field.obj 2>&1 \
        | grep -o "[0-9]* iterations in [0-9.]* s ([0-9.]* ms per iteration)"
      awk -F, '$1 == 20 { a = $5 } $1 == 80 { b = $5 } END { printf "steady: %.2f ms per iteration\n", (b - a) / 60 * 1000 }' /tmp/round7-field-report/loss.csv
    done
  done
done
echo "== done $(uptime)"
