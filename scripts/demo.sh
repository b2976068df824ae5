#!/usr/bin/env bash
# The main job, end to end on the MuJoCo stub: check a preset trajectory, play it with every
# interlock armed while recording camera frames and telemetry, then report and score the run.
set -euo pipefail
cd "$(dirname "$0")/.."
HITL=./target/release/hitl
PRESET=${PRESET:-trajectories/presets/flyaround-demo.npz}
OUT=${OUT:-runs/demo}
mkdir -p "$OUT"

echo "== hitl check $PRESET"
$HITL check "$PRESET"

echo
echo "== hitl run $PRESET --record $OUT/run.mcap (embedded MuJoCo stub)"
$HITL run "$PRESET" --record "$OUT/run.mcap" --camera sim --light sim --perception icp --plain

echo
echo "== hitl report $OUT/run.mcap"
$HITL report "$OUT/run.mcap" --out "$OUT/report"

echo
echo "== hitl eval $OUT/run.mcap"
$HITL eval "$OUT/run.mcap"
echo
echo "Open $OUT/report/index.html for the plots."
