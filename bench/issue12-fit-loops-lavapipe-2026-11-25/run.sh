#!/bin/bash
# Issue #12, the field and pose fits at k iterations per submission: before / after, alternating
# rounds on one machine. `run.sh BEFORE_BIN AFTER_BIN FIELD_STUDY_BIN ROUNDS` (build the before
# binary from 3b48cda and the after one, and `cargo build --release --example field_study`,
# first). Writes run.log beside it. Run it on a quiet machine.
set -euo pipefail
before=$1; after=$2; study=$3; rounds=${4:-3}
here=$(cd "$(dirname "$0")" && pwd)
assets=$(cd "$here/../../assets" && pwd)
work=$(mktemp -d)
log="$here/run.log"
: > "$log"
say() { echo "$@" | tee -a "$log"; }
say "date $(date -u +%FT%TZ); device: $("$after" info 2>&1 | grep -m1 -i 'device' || true)"
# Field fit: setup A of RESULTS.md (spot, 24 views of 64², viewing angle 15°), fit-field's
# defaults (150 iterations, log every 10).
"$study" write "$work/fs" va=15 > /dev/null
# Pose fit: spot seen from elevation 20°, azimuth 30°, from 20° off, fit-pose's defaults.
"$after" render --mesh "$assets/spot_triangulated.obj" --out "$work/target.png" --size 48 \
  --distance 2.732 --elevation 20 --azimuth 30 > /dev/null
for r in $(seq 1 "$rounds"); do
  for b in before after; do
    bin=${!b}
    say "round $r $b field: $("$bin" fit-field --silhouettes "$work/fs/silhouettes" \
      --cameras "$work/fs/cameras.csv" --out "$work/field-$b.obj" 2>&1 | tail -1 | cut -c1-60)"
    say "round $r $b pose: $("$bin" fit-pose --mesh "$assets/spot_triangulated.obj" \
      --target "$work/target.png" --out "$work/pose-$b.json" --distance 2.732 --elevation 20 \
      --azimuth 30 --init-rotation 0,20,10 --quiet 2>&1 | tail -1 | cut -c1-160)"
  done
done
if cmp -s "$work/field-before.obj" "$work/field-after.obj"; then
  say "field: the fitted surfaces are byte-identical"
else
  say "field: the fitted surfaces DIFFER"
fi
say "load: $(uptime)"
"$after" bench --scene fit-pose --scene fit-field --repeat 9 2>&1 | grep -E "fit-(iteration|loop)" \
  | cut -c1-600 | tee -a "$log"
rm -rf "$work"
