# Two commands do all set-up on a fresh clone:
#   make run   installs what is missing, builds, serves on 127.0.0.1:8080 with data in ./data
#   make test  installs what is missing (and the test tools), checks formatting and clippy
#              (make lint), then runs the whole test suite
# One cargo profile (release) throughout, so libtorch's torch-sys is compiled once.
SHELL := /bin/bash
export PATH := $(HOME)/.cargo/bin:$(PATH)

.PHONY: run test lint setup setup-test build bench

run: build
	./target/release/choreo serve --bind 127.0.0.1:8080 --data-dir ./data

test: setup-test
	@$(MAKE) --no-print-directory lint
	cargo test --release

# The gates before the suite: rustfmt's layout, and clippy on every target (library, binaries,
# tests) with warnings as errors. With a warm target/ they take about half a minute, where the
# suite takes twenty. --release, so that clippy reuses the test build's build-script outputs
# (torch-sys's C++ shim) instead of building them again for a second profile. Needs `make setup`
# first.
lint:
	@echo "lint: cargo fmt --check"
	@cargo fmt --check || { echo "lint: formatting differs from rustfmt's (diff above); run \`cargo fmt\`" >&2; exit 1; }
	@echo "lint: cargo clippy --release --all-targets -- -D warnings"
	@cargo clippy --release --all-targets -- -D warnings || { echo "lint: clippy failed (above); fix the code, or allow the lint on that one item with a comment saying why" >&2; exit 1; }

setup:
	bash scripts/setup.sh

setup-test:
	bash scripts/setup.sh --test

build: setup
	cargo build --release

# Not a test: GET /v1/jobs/{id} throughput and p99 while the workers are busy.
bench: build
	./target/release/choreo bench http --seconds 10
