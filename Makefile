# hitl: two commands on a fresh Linux machine with the Rust toolchain, Python 3 and pip.
#   make demo   set up, then run a stub campaign: play a preset trajectory, record it, report it
#   make test   set up, build the trigger box's firmware and box-sim, then run every test (Rust,
#               Python peers, the firmware in box-sim through hitl), fmt and clippy. The tests
#               build with --release: they reuse `make demo`'s optimised dependencies (hitl and
#               hitl-perception are built again with every feature; Cargo.toml says why).
#   make firmware / firmware-check   the trigger box's firmware and box-sim (docs/trigger-box.md)
SHELL := /bin/bash
CARGO ?= cargo

.PHONY: all setup setup-libs build demo test test-rust lint bench clean-deps test-lerobot test-slurm

all: build

setup:
	@bash scripts/setup.sh

# Debian packages and shared libraries only (no Python test peers).
setup-libs:
	@bash scripts/setup.sh --no-peers

build: setup
	$(CARGO) build --release

# The demo builds what it runs (the stub; not the exporter, the mono and ONNX backends: Cargo.toml's
# features) and needs the shared libraries but none of the Python test peers; `make build`,
# `make test` and `make bench` build everything.
demo: setup-libs
	$(CARGO) build --release --no-default-features --features stub
	@bash scripts/demo.sh

# The trigger box's firmware and box-sim first: tests/trigger_box_sim.rs runs `hitl` against them.
test: setup-libs firmware test-rust lint

# The Python test peers install while the tests build (the build needs none of them). With
# cargo-nextest installed the test binaries then run side by side (.config/nextest.toml keeps
# apart what must not share the machine); without it, cargo test runs them one after another.
# Doc tests run when a doc comment holds one (none does today: examples live in tests/; rustdoc
# took 74 s to find none).
NEXTEST := $(shell $(CARGO) nextest --version >/dev/null 2>&1 && echo yes)
test-rust:
	@bash scripts/setup.sh --peers-only > .deps/setup-peers.log 2>&1 & peers=$$!; \
	  $(CARGO) test --release --workspace --all-targets --no-run; built=$$?; \
	  wait $$peers || { cat .deps/setup-peers.log; exit 1; }; cat .deps/setup-peers.log; \
	  exit $$built
ifeq ($(NEXTEST),yes)
	$(CARGO) nextest run --release --workspace --all-targets --no-fail-fast
else
	@echo "no cargo-nextest: cargo test runs the test binaries one after another"
	$(CARGO) test --release --workspace --all-targets --no-fail-fast
endif
	@if bash scripts/has_doctests.sh; then $(CARGO) test --release --workspace --doc; \
	  else echo "no doc tests in the crates' docs (examples live in tests/)"; fi

# lint: rustfmt, clippy on everything, and clippy on the controller without its optional features
# (no stub, exporter, mono or ONNX backend: a real-hardware-only build must build clean too).
# Clippy with --release reuses `make demo`'s build scripts and proc macros (ruckig's C++,
# bindings): in the dev profile it built them all again, 6 min 48 s from an empty target/debug
# against 3 min here. The stub-less pass selects the
# whole workspace so that dependencies keep the features the first pass checked them with: only
# hitl and hitl-perception are checked again (`-p hitl` alone re-checked a third of the tree,
# 58 s); the price is that a dependency feature only the stub asks for would not be noticed missing.
# check_shared_features.py: make demo's and make test's builds ask every shared crate for the
# same features (else make test rebuilds it and everything above it).
lint:
	$(CARGO) fmt --all -- --check
	@python3 scripts/check_shared_features.py
	$(CARGO) clippy --release --workspace --all-targets -- -D warnings
	$(CARGO) clippy --release --workspace --lib --bins --no-default-features -- -D warnings

# Opt-in: a full LeRobotDataset round trip of `hitl export lerobot` (docs/lerobot-export.md).
# LeRobot >= 0.6 (depth maps) needs Python >= 3.12: PYTHON312 names one. A run an interlock
# stops (exit 4) still leaves a recording of the captures made so far, which is exported.
PYTHON312 ?= python3.12
test-lerobot: setup
	$(CARGO) build
	@command -v $(PYTHON312) >/dev/null || { echo "test-lerobot: no $(PYTHON312) (set PYTHON312=...)"; exit 1; }
	@[ -x .venv-lerobot/bin/python ] || $(PYTHON312) -m venv .venv-lerobot
	.venv-lerobot/bin/pip install --quiet 'lerobot[dataset]>=0.6' pyarrow av
	rm -rf runs/test-lerobot && mkdir -p runs/test-lerobot
	target/debug/hitl plan --preset flyaround --range-m 10 --duration-s 20 --capture-every 20 --out runs/test-lerobot/fly.npz
	target/debug/hitl run runs/test-lerobot/fly.npz --record runs/test-lerobot/run.mcap --camera sim --camera-preset wfov --camera-size 320x256 --light sim --plain --config tests/data/shared-vm-lab.toml || [ $$? -eq 4 ]
	target/debug/hitl export lerobot runs/test-lerobot/run.mcap --out runs/test-lerobot/dataset
	.venv-lerobot/bin/python scripts/validate_lerobot.py runs/test-lerobot/dataset --lerobot

# Opt-in: a real single-node Slurm on this machine (munge, slurmctld, slurmd; loopback only; needs
# root) plays a 4-case campaign as a job array (docs/campaigns.md).
test-slurm: setup
	$(CARGO) build
	bash scripts/slurm/test.sh

bench: setup
	$(CARGO) build --release
	@bash scripts/bench.sh

clean-deps:
	rm -rf .deps .venv

include firmware/firmware.mk
