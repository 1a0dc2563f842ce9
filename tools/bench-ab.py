#!/usr/bin/env python3
"""Alternating A/B runs of softvk binaries on one `softvk bench` scene.

    tools/bench-ab.py [--rounds N] [--repeat N] SCENE BASE BIN...

Each round runs every binary once, in a shuffled order,

    BIN bench --scene SCENE --tile 8 --no-brute --repeat N --json FILE

and reads its JSON records. A 2-core CPU device drifts by up to 2x in speed over minutes, so
single figures of two binaries taken minutes apart say little: within one round the drift falls
on every binary alike, and the ratio to BASE in that round cancels most of it. Prints, per binary
and record (`forward`, `backward`, `forward+backward` for a render scene; `fit-iteration`,
`fit-loop-k1`, `fit-loop-k10` for `fit-120` and `fit-pose`; `fit-iteration` for `fit-field`):
the min and median GPU and wall ms over the rounds, the median of the per-round wall ratios to
BASE, and the median of every pass. Run it on a quiet machine (the load average is printed per
round). The before/after figures of BENCHMARKS.md were taken this way; `SOFTVK_ASSETS` is
passed through to the binaries.

A tool around `softvk bench`, not a benchmark of its own: it compares binaries' speed as
`tools/output-hashes` compares their outputs.
"""
import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile


def run(binary, scene, repeat, out):
    cmd = [binary, "bench", "--scene", scene, "--tile", "8", "--no-brute",
           "--repeat", str(repeat), "--json", out]
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{done.stdout}")
    with open(out) as f:
        return {r["pass"]: r for r in json.load(f)}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--rounds", type=int, default=9)
    p.add_argument("--repeat", type=int, default=9, help="timed submissions per run (medians)")
    p.add_argument("scene")
    p.add_argument("base")
    p.add_argument("bins", nargs="+")
    a = p.parse_args()
    bins = [a.base] + a.bins
    runs = [[] for _ in bins]  # per binary (by position: the same path may appear twice)
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.rounds):
            print(f"round {r + 1}: load {os.getloadavg()[0]:.2f}", file=sys.stderr)
            order = list(range(len(bins)))
            random.Random(r).shuffle(order)
            for i in order:
                runs[i].append(run(bins[i], a.scene, a.repeat, os.path.join(tmp, f"{i}.json")))
    med = statistics.median
    for i, b in enumerate(bins):
        print(b)
        for name in runs[i][0]:
            recs = [rnd[name] for rnd in runs[i]]
            gpu = [x["gpu_ms"] for x in recs if x["gpu_ms"] is not None]
            wall = [x["wall_ms"] for x in recs]
            if all(name in base for base in runs[0]):
                ratio = med(x["wall_ms"] / base[name]["wall_ms"]
                            for x, base in zip(recs, runs[0]))
                ratio_s = f"; wall / base {ratio:.3f} (median of per-round ratios)"
            else:
                ratio_s = ""
            gpu_s = f"gpu min {min(gpu):.2f} median {med(gpu):.2f}, " if gpu else ""
            print(f"  {name}: {gpu_s}wall min {min(wall):.2f} median {med(wall):.2f} ms{ratio_s}")
            passes = ", ".join(f"{k} {med(x['passes'].get(k, 0.0) for x in recs):.2f}"
                               for k in recs[0]["passes"])
            print(f"    {passes}")


if __name__ == "__main__":
    main()
