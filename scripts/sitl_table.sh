#!/usr/bin/env bash
# The README's SITL table (the paper's Table 3 metrics) in one command: the campaigns/sitl-table.toml
# preset (20 s fly-arounds at 5, 10, 25, 50 m with the WFOV camera at 1280x1024, three built-in
# targets, the ICP tracker on the ground-truth mesh) played by `hitl campaign run` into runs/sitl,
# then tabulated by `hitl campaign collect` (Markdown on stdout, runs/sitl/results.csv, plots).
# A rerun skips the cases already done; `rm -rf runs/sitl` starts afresh.
#   usage: scripts/sitl_table.sh [RANGES...]   (default: the preset's 5 10 25 50)
#   SIZE=WxH changes the camera resolution; HITL=path picks the binary; JOBS=N cases at a time.
set -euo pipefail
cd "$(dirname "$0")/.."
HITL=${HITL:-./target/release/hitl}
OUT=${OUT:-runs/sitl}
MANIFEST=campaigns/sitl-table.toml
if [ $# -gt 0 ] || [ -n "${SIZE:-}" ]; then
  # A variant of the preset: the same table with other ranges or another resolution.
  mkdir -p "$OUT"
  ranges=$(IFS=,; echo "${*:-5,10,25,50}")
  sed -e "s/^camera_size = .*/camera_size = \"${SIZE:-1280x1024}\"/" \
      -e "s/^range_m = .*/range_m = [${ranges}]/" "$MANIFEST" >"$OUT/sitl-table.toml"
  MANIFEST="$OUT/sitl-table.toml"
fi
code=0
"$HITL" campaign run "$MANIFEST" --out "$OUT" ${JOBS:+--jobs "$JOBS"} || code=$?
"$HITL" campaign collect "$OUT"
exit "$code"
