#!/bin/bash
# Issue #12: the fitting iterations before (24e1d26, the commit before the record-only stages)
# and after (the binary given as $1), alternating rounds on one quiet machine. The before binary:
#   git worktree add --detach /work/wt-old 24e1d26 && (cd /work/wt-old && cargo build --release --bin softvk)
B=${BEFORE:-/work/wt-old/target/release/softvk}; A=${1:?after binary}
OUT=$(dirname "$0"); cd "$OUT" || exit 1
for r in 1 2; do
  for w in before after; do
    bin=$B; [ $w = after ] && bin=$A
    echo "== fit-120 $w round $r $(uptime)"
    $bin bench --scene fit-120 --repeat 3 --json fit-120-$w-$r.json 2>&1 | grep -v "^$"
  done
done
for r in 1 2; do
  for w in before after; do
    bin=$B; [ $w = after ] && bin=$A
    rm -rf /tmp/demo-$w
    echo "== demo (fit-mesh, 8 views x 64^2, 200 iterations) $w round $r $(uptime)"
    $bin demo --out /tmp/demo-$w 2>&1 | tail -1
  done
done
cmp /tmp/demo-before/fitted.obj /tmp/demo-after/fitted.obj && echo "demo: fitted meshes identical"
echo "== done $(uptime)"
