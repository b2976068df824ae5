#!/usr/bin/env bash
# The paper's Table 3 in SITL, one command: for each range (WFOV camera) and each built-in target,
# plan a fly-around, play it on the MuJoCo stub with the ray-cast camera and the ICP tracker
# (ground-truth mesh), and score it with hitl eval. Prints a Markdown table of the mean e_t
# (real metres, and % of range) and mean e_r (degrees), and keeps every JSON under runs/sitl/.
# The camera renders at the paper's WFOV sensor resolution, 1280x1024 (SIZE=WxH to change it): at
# 50 m the 2 m target spans about 60 pixels there, 15 at 320x256.
#   usage: scripts/sitl_table.sh [RANGES...]      (default: 5 10 25 50)
set -euo pipefail
cd "$(dirname "$0")/.."
HITL=${HITL:-./target/release/hitl}
OUT=runs/sitl
SIZE=${SIZE:-1280x1024}
mkdir -p "$OUT"
RANGES=("$@"); [ ${#RANGES[@]} -gt 0 ] || RANGES=(5 10 25 50)
echo "| range | target | run exit | frames | failures | mean e_t [m] | e_t / range | mean e_r [deg] |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- |"
for r in "${RANGES[@]}"; do
  plan="$OUT/flyaround-${r}m.npz"
  $HITL plan --preset flyaround --range-m "$r" --duration-s 20 --capture-every 5 --out "$plan" >/dev/null
  for target in asymmetric one-plane two-planes; do
    rec="$OUT/${r}m-$target.mcap"
    # A run an interlock stopped (exit 4) is still scored over the frames it recorded.
    code=0
    $HITL run "$plan" --record "$rec" --camera sim --camera-preset wfov --camera-size "$SIZE" \
      --light sim --perception icp --target-model "$target" --plain >"$OUT/${r}m-$target.log" 2>&1 || code=$?
    $HITL eval "$rec" --json >"$OUT/${r}m-$target.json" || echo '{}' >"$OUT/${r}m-$target.json"
    python3 - "$OUT/${r}m-$target.json" "$r" "$target" "$code" <<'PY'
import json, sys
m = json.load(open(sys.argv[1])); r = float(sys.argv[2])
et, er = m.get("mean_et_m"), m.get("mean_er_deg")
pct = f"{100 * et / r:.3f} %" if et is not None else "-"
print(f"| {r:g} m | {sys.argv[3]} | {sys.argv[4]} | {m.get('frames')} | {m.get('failures')} | "
      f"{et if et is None else round(et, 4)} | {pct} | {er if er is None else round(er, 2)} |")
PY
  done
done
