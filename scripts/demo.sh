#!/usr/bin/env bash
# The main job, end to end on the MuJoCo stub: plan a 10 m fly-around from the paper's orbital
# mechanics, preflight it, play it with every interlock armed while the simulated camera captures
# frames and the ICP tracker estimates the target's pose, record everything, then report and
# score the run with the paper's metrics.
set -euo pipefail
cd "$(dirname "$0")/.."
HITL=./target/release/hitl
OUT=${OUT:-runs/demo}
mkdir -p "$OUT"

echo "== hitl plan: 10 m fly-around, 20 s, a capture every 5th waypoint"
$HITL plan --preset flyaround --range-m 10 --duration-s 20 --capture-every 5 --out "$OUT/flyaround-10m.npz"

echo
echo "== hitl check (preflight)"
$HITL check "$OUT/flyaround-10m.npz"

echo
echo "== hitl run on the embedded MuJoCo stub (lab scene, Orbbec camera at 1280x800), recording to $OUT/run.mcap"
$HITL run "$OUT/flyaround-10m.npz" --record "$OUT/run.mcap" --camera sim --camera-preset orbbec --camera-size 1280x800 \
  --scene-kind lab --light sim --perception icp --plain

echo
echo "== hitl report"
$HITL report "$OUT/run.mcap" --out "$OUT/report"

echo
echo "== hitl eval (the paper's metrics: e_t in real metres, e_r in degrees)"
$HITL eval "$OUT/run.mcap"
echo
echo "Report (with the contact sheet of frames and silhouettes): $OUT/report/index.html"
