#!/usr/bin/env bash
# Two public meshes from outside the project for the tracker bench (issue 23): the Stanford bunny
# (Stanford 3D Scanning Repository, holes repaired) and the kitten (Frank B. ter Haar, AIM@SHAPE),
# as OBJ files in a public collection of sample models, pinned by commit and checked by SHA-256.
# Nothing is committed: they land in runs/meshes/ (ignored).
#   usage: scripts/fetch_meshes.sh [DIR]     then: hitl bench tracker --target-model DIR/bunny.obj
set -euo pipefail
cd "$(dirname "$0")/.."
DIR=${1:-runs/meshes}
BASE=https://raw.githubusercontent.com/jcracken/prog04-jcracken-reupload/98adf15257f6de5862bafa2c1713fbe58f0607ba
mkdir -p "$DIR"
fetch() {
  local name=$1 sum=$2
  if ! echo "$sum  $DIR/$name" | sha256sum --check --status 2>/dev/null; then
    curl -fsSL "$BASE/$name" -o "$DIR/$name.part"
    mv "$DIR/$name.part" "$DIR/$name"
  fi
  echo "$sum  $DIR/$name" | sha256sum --check --quiet
}
fetch bunny.obj 18f2c0bddc6612c452ad76a8383a81040f3b313ce18a357a6050678715e05b79
fetch kitten.obj fce8721135d6ed579b369d2d41aa05bc1cae2043b5797a86243d2c3f1f8070c7
echo "$DIR/bunny.obj $DIR/kitten.obj"
