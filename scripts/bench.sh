#!/usr/bin/env bash
# Every benchmark, one JSON object each, into runs/bench/ (the README's figures come from these).
set -euo pipefail
cd "$(dirname "$0")/.."
HITL=./target/release/hitl
OUT=runs/bench
mkdir -p "$OUT"
run() {
  local name=$1; shift
  echo "== hitl bench $name $*"
  $HITL bench "$name" --json "$@" | tee "$OUT/$name.json"
}
run loop --seconds 60 --load
run npz
run ik
run protocol
run render
run record --seconds 10
run tracker
run accuracy
echo "figures in $OUT/"
