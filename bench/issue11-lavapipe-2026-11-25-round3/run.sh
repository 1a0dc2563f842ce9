#!/bin/bash
# One quiet run: issue #11 round three (square subgroup blocks). Binaries:
#   before = 24baecf (the commit before issue #11's work), head = dbdf04a (round two + #12),
#   after = f928936 (square blocks, vec4 partials, vec4 colours); each built with `cargo build --release` in a worktree of that commit.
# spot-256 forward+backward alternately, three rounds; fit-120 once each.
export SOFTVK_ASSETS=/work/shared/assets
B=/work/bin-before; H=/work/bin-head; A=/work/bin-after
OUT=${OUT:-/work/q/round3}; mkdir -p $OUT && cd $OUT && rm -f *.json
for r in 1 2 3; do
  for w in before head after; do
    bin=$B; [ $w = head ] && bin=$H; [ $w = after ] && bin=$A
    echo "== spot-256 $w round $r $(uptime)"
    $bin bench --scene spot-256 --tile 8 --no-brute --repeat 9 --json spot-256-$w-$r.json 2>&1 | grep -v "^$"
  done
done
for w in before head after; do
  bin=$B; [ $w = head ] && bin=$H; [ $w = after ] && bin=$A
  echo "== fit-120 $w $(uptime)"
  $bin bench --scene fit-120 --repeat 3 --json fit-120-$w.json 2>&1
done
echo "== done $(uptime)"
