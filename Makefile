# hitl: two commands on a fresh Linux machine with the Rust toolchain, Python 3 and pip.
#   make demo   set up, then run a stub campaign: play a preset trajectory, record it, report it
#   make test   set up, then run every test (Rust, Python peers), fmt and clippy
SHELL := /bin/bash
CARGO ?= cargo

.PHONY: all setup build demo test test-rust lint bench clean-deps test-slurm

all: build

setup:
	@bash scripts/setup.sh

build: setup
	$(CARGO) build --release

demo: setup
	$(CARGO) build --release
	@bash scripts/demo.sh

test: setup test-rust lint

test-rust:
	$(CARGO) test --workspace --all-targets --no-fail-fast
	$(CARGO) test --workspace --doc

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

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
