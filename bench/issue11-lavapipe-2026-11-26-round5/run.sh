#!/bin/bash
# One quiet run: issue #11 round five. Binaries, each `cargo build --release` of the commit named:
#   before = 24baecf (the commit before issue #11's work), r4 = 7f5f3db (main before this round),
#   new = 43980be (this round).
# spot-256 forward+backward alternately (order rotated per round), nine rounds; then fit-120
# once each of before, r4 and new.
export SOFTVK_ASSETS=${SOFTVK_ASSETS:-/work/shared/assets}
declare -A BIN=([before]=/work/bin/before-24baecf [r4]=/work/bin/r4-7f5f3db [new]=/work/bin/new)
OUT=${OUT:-$(dirname "$0")}; mkdir -p "$OUT" && cd "$OUT" && rm -f spot-256-*.json fit-120-*.json
names=(before r4 new)
for r in 1 2 3 4 5 6 7 8 9; do
  for i in 0 1 2; do
    w=${names[$(( (i + r) % 3 ))]}
    echo "== spot-256 $w round $r $(uptime)"
    ${BIN[$w]} bench --scene spot-256 --tile 8 --no-brute --repeat 9 --json spot-256-$w-$r.json 2>&1 | grep "forward+backward:"
  done
done
for w in before r4 new; do
  echo "== fit-120 $w $(uptime)"
  ${BIN[$w]} bench --scene fit-120 --repeat 3 --json fit-120-$w.json 2>&1 | grep -v "^$" | grep -v '^\[\|^  {\|^\]'
done
echo "== done $(uptime)"
