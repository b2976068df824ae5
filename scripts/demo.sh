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

echo "== hitl plan: 10 m fly-around, 20 s, a capture every 5th waypoint, the Sun behind the chaser"
# The Sun in ECI -x lights the side the chaser sees (the default, +x, backlights this orbit).
$HITL plan --preset flyaround --range-m 10 --duration-s 20 --capture-every 5 --sun-eci=-1,0,0 \
  --out "$OUT/flyaround-10m.npz"

echo
echo "== hitl check (preflight)"
$HITL check "$OUT/flyaround-10m.npz"

echo
echo "== hitl run on the embedded MuJoCo stub (orbit scene, Orbbec camera at 1280x800), recording to $OUT/run.mcap"
# --no-retreat: the simulated arm stays where the orbit ends; its 16 s retreat to the rest pose
# would show nothing the approach does not (a run retreats by default; `hitl park` also returns).
$HITL run "$OUT/flyaround-10m.npz" --record "$OUT/run.mcap" --camera sim --camera-preset orbbec --camera-size 1280x800 \
  --scene-kind orbit --light sim --perception icp --plain --no-retreat

echo
echo "== hitl report"
$HITL report "$OUT/run.mcap" --out "$OUT/report" --contact-zoom 1.5

echo
echo "== hitl eval (the paper's metrics: e_t in real metres, e_r in degrees)"
$HITL eval "$OUT/run.mcap"
echo
echo "Report (with the contact sheet of frames and silhouettes): $OUT/report/index.html"
