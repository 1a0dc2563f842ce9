#!/bin/bash
# Alternating rounds of spot-256 tiled 8 forward+backward, before vs after.
cd /work/main
for i in $(seq $1); do for b in before after; do
  /tmp/exp/bin-$b bench --scene spot-256 --tile 8 --no-brute --repeat 9 --json /tmp/exp/r-$b-$i.json > /tmp/exp/r-$b-$i.log 2>&1
  f=$(grep "tiled 8: gpu" /tmp/exp/r-$b-$i.log | grep -o "gpu [0-9.]* ms" | head -1)
  fb=$(grep "tiled 8 forward+backward:" /tmp/exp/r-$b-$i.log | grep -o "gpu [0-9.]* ms" | head -1)
  echo "$i $b forward $f forward+backward $fb"
done; done
