#!/bin/bash
# issue #11 round seven: a second spot-256 forward+backward run minutes after run.sh's (quiet),
# before (24baecf) and new alternately, nine rounds, order rotated: run.sh's rounds gave r6 and
# new (the same fine-pass kernels) 8.28x and 7.97x, so the machine's drift is within that.
export SOFTVK_ASSETS=${SOFTVK_ASSETS:-/work/shared/assets}
declare -A BIN=([before]=/work/bin/before-24baecf [new]=/work/bin/r7)
cd "$(dirname "$0")" && rm -f spot-256-second-*.json
names=(before new)
for r in 1 2 3 4 5 6 7 8 9; do
  for i in 0 1; do
    w=${names[$(( (i + r) % 2 ))]}
    echo "== spot-256 $w round $r $(uptime)"
    ${BIN[$w]} bench --scene spot-256 --tile 8 --no-brute --repeat 9 --json spot-256-second-$w-$r.json 2>&1 | grep "forward+backward:"
  done
done
echo "== done $(uptime)"
