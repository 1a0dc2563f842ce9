#!/bin/bash
# Alternating A/B of softvk binaries on spot-256 forward+backward: `ab.sh ROUNDS BIN...`.
# Each round runs every binary once (`softvk bench --scene spot-256 --tile 8 --no-brute
# --repeat 5`); prints per binary the min and median over rounds of raster tiled, grad tiled and
# forward+backward GPU ms. Run it on a quiet machine (this machine's speed drifts by up to 2×
# over minutes: alternate, and compare within one run only).
set -euo pipefail
R=$1; shift
out=$(mktemp)
for r in $(seq 1 "$R"); do
  for b in "$@"; do
    "$b" bench --scene spot-256 --tile 8 --no-brute --repeat 5 2>&1 | grep "forward+backward:" |
      sed -E "s|.*gpu ([0-9.]+) ms.*\[.*raster tiled ([0-9.]+), grad tiled ([0-9.]+),.*|$b \1 \2 \3|" >> "$out"
  done
done
python3 - "$out" <<'PY'
import collections, statistics, sys
d = collections.defaultdict(list)
for line in open(sys.argv[1]):
    b, fb, r, g = line.split()
    d[b].append((float(fb), float(r), float(g)))
for b, v in d.items():
    col = lambda i: [x[i] for x in v]
    print(f"{b}: raster min {min(col(1)):.2f} med {statistics.median(col(1)):.2f} | "
          f"grad min {min(col(2)):.2f} med {statistics.median(col(2)):.2f} | "
          f"fb min {min(col(0)):.2f} med {statistics.median(col(0)):.2f}")
PY
rm -f "$out"
uptime
