#!/usr/bin/env python3
"""Check that `make demo`'s build and `make test`'s build ask every shared crate for the same
features, so that `make test` reuses the demo's artefacts instead of rebuilding (a crate built
with other features is another artefact, and so is every crate above it: one such crate under
nalgebra rebuilt all of ours). Exit 1 naming each crate that differs and the features only the
tests' build asks for; pin them in Cargo.toml's feature-unification block."""
import re
import subprocess
import sys

TARGET = "x86_64-unknown-linux-gnu"
# Features `cargo tree` reports from other targets' dependencies (wasm, Windows), which a Linux
# build never enables; and the crates whose features are meant to differ.
OTHER_TARGETS = {"wasm_js", "wasm", "windows-sys", "visit", "visit-mut"}
GATED = {"hitl", "hitl-perception"}


def features(args):
    out = subprocess.run(
        ["cargo", "tree", "--target", TARGET, "--prefix", "none", "-f", "{p} [{f}]", *args],
        check=True, capture_output=True, text=True,
    ).stdout
    found = {}
    for line in out.splitlines():
        m = re.match(r"(\S+) (v\S+)(?: \(.*?\))? \[(.*?)\]", line)
        if m:
            found.setdefault((m[1], m[2]), set()).update(f for f in m[3].split(",") if f)
    return found


demo = features(["--no-default-features", "--features", "stub", "-p", "hitl", "-e", "normal,build"])
tests = features(["--workspace", "--all-targets", "-e", "normal,build,dev"])
bad = []
for key, want in sorted(demo.items()):
    if key[0] in GATED or key not in tests:
        continue
    extra = tests[key] - want - OTHER_TARGETS
    missing = want - tests[key]
    if extra or missing:
        bad.append(f"  {key[0]} {key[1]}: tests add {sorted(extra)}, lack {sorted(missing)}")
if bad:
    print("shared crates built with other features by make test than by make demo:")
    print("\n".join(bad))
    sys.exit(1)
print(f"shared features: the demo's {len(demo)} crates are built alike by make test")
