#!/usr/bin/env bash
# Exit 0 when a doc comment in the crates' sources opens a code block rustdoc would run as a doc
# test (a fence with no language, or rust, no_run, should_panic, compile_fail), 1 otherwise.
# One awk over every file (a few hundred short paths: xargs does not split them).
cd "$(dirname "$0")/.."
find src hal drivers trajectories sim-stub record perception calib -path '*/src/*' -name '*.rs' -print0 |
  xargs -0 awk '
    FNR == 1 { open = 0 }
    /^[[:space:]]*\/\/[\/!][[:space:]]*```/ {
      info = $0; sub(/.*```/, "", info)
      if (!open) { open = 1; if (info == "" || info ~ /rust|no_run|should_panic|compile_fail/) found = 1 }
      else open = 0
    }
    END { exit found ? 0 : 1 }' || exit 1
