#!/bin/bash
cd /work/main
D=bench/issue14-blurry-1024-2026-11-24
{
echo "commit $(git rev-parse --short HEAD) + working tree (tile windows); $(date -u)"; uptime
/usr/bin/time -v ./target/release/softvk bench --scene blurry-1024 --tile 8 --brute-repeat 1 --repeat 1 --forward-only --json $D/forward.json
uptime
/usr/bin/time -v ./target/release/softvk bench --scene blurry-1024 --tile 8 --no-brute --backward-only --repeat 1 --json $D/backward.json
uptime; date -u
} > $D/run.log 2>&1
