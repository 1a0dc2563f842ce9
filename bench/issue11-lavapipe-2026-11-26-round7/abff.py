#!/usr/bin/env python3
"""Paired A/B of softvk binaries on the fit-field bench scene: `abff.py ROUNDS REPEAT BASE BIN...`.
Each round runs every binary once in a shuffled order (`softvk bench --scene fit-field --repeat
REPEAT`, medians of REPEAT iterations); prints per binary the median wall / GPU ms and per-pass
medians, and the median of the per-round wall ratios to BASE."""
import random, re, statistics, subprocess, sys
rounds, repeat, bins = int(sys.argv[1]), sys.argv[2], sys.argv[3:]
pat = re.compile(r"gpu ([0-9.]+) ms, wall ([0-9.]+) ms \(medians of \d+\) \[(.*)\]")
runs = {b: [] for b in bins}
for r in range(rounds):
    order = bins[:]
    random.Random(r).shuffle(order)
    for b in order:
        out = subprocess.run([b, "bench", "--scene", "fit-field", "--repeat", repeat],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True).stdout
        m = pat.search(out)
        if not m:
            print(out); sys.exit(1)
        passes = {}
        for part in m.group(3).split(","):
            name, _, v = part.rstrip().rpartition(" ")
            passes[name.strip("\n")] = float(v)
        runs[b].append((float(m.group(1)), float(m.group(2)), passes))
base = runs[bins[0]]
for b in bins:
    v = runs[b]
    print(f"{b}: gpu {statistics.median(x[0] for x in v):.2f} wall {statistics.median(x[1] for x in v):.2f} "
          f"(per round {' '.join(f'{x[1]:.1f}' for x in v)}) ratio to base {statistics.median(x[1]/y[1] for x, y in zip(v, base)):.3f}")
    names = list(v[0][2].keys())
    print("   " + ", ".join(f"{n.strip()} {statistics.median(x[2].get(n, 0) for x in v):.2f}" for n in names))
