#!/bin/bash
# One quiet run: issue #11 before (24baecf) / after (HEAD) on spot-256 and fit-120; fit-field after.
export SOFTVK_ASSETS=/work/shared/assets
B=/tmp/before-24baecf/target/release/softvk; A=/tmp/exp/bin-final
cd /tmp/q && rm -f *.json
for r in 1 2 3; do
  for w in before after; do
    bin=$B; [ $w = after ] && bin=$A
    echo "== spot-256 $w round $r $(uptime)"
    $bin bench --scene spot-256 --tile 8 --no-brute --repeat 9 --json spot-256-$w-$r.json 2>&1 | grep -v "^$"
  done
done
for r in 1 2; do
  echo "== fit-field after round $r $(uptime)"
  $A bench --scene fit-field --repeat 9 --json fit-field-after-$r.json 2>&1
done
echo "== fit-120 before $(uptime)"
$B bench --scene fit-120 --repeat 3 --json fit-120-before.json 2>&1
for r in 1 2; do
echo "== fit-120 after round $r $(uptime)"
$A bench --scene fit-120 --repeat 3 --json fit-120-after-$r.json 2>&1
done
echo "== done $(uptime)"
