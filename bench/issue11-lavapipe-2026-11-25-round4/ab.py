#!/usr/bin/env python3
"""Paired A/B of softvk binaries on spot-256 forward+backward: `ab.py ROUNDS BASE BIN...`.

Each round runs every binary once, in a shuffled order (`softvk bench --scene spot-256 --tile 8
--no-brute --repeat 5`, medians of 5), and takes each binary's ratio to BASE in that round: this
machine's speed drifts by up to 2x over minutes, and a ratio within one round cancels most of
it. Prints per binary the min and median of raster tiled, grad tiled and forward+backward GPU ms
and the median of the per-round ratios to BASE. Run it on a quiet machine."""
import random, re, statistics, subprocess, sys

rounds, bins = int(sys.argv[1]), sys.argv[2:]
pat = re.compile(r"forward\+backward: gpu ([0-9.]+) ms.*raster tiled ([0-9.]+), grad tiled ([0-9.]+),")
runs = {b: [] for b in bins}
for r in range(rounds):
    order = bins[:]
    random.Random(r).shuffle(order)
    for b in order:
        out = subprocess.run([b, "bench", "--scene", "spot-256", "--tile", "8", "--no-brute",
                              "--repeat", "5"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True).stdout
        m = pat.search(out)
        runs[b].append(tuple(float(x) for x in m.groups()))
base = runs[bins[0]]
for b in bins:
    v = runs[b]
    col = lambda i: [x[i] for x in v]
    ratio = lambda i: statistics.median(x[i] / y[i] for x, y in zip(v, base))
    print(f"{b}: raster min {min(col(1)):.2f} med {statistics.median(col(1)):.2f} | grad min "
          f"{min(col(2)):.2f} med {statistics.median(col(2)):.2f} | fb min {min(col(0)):.2f} med "
          f"{statistics.median(col(0)):.2f} | ratio to base: raster {ratio(1):.3f} grad "
          f"{ratio(2):.3f} fb {ratio(0):.3f}")
