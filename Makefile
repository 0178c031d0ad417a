# Two commands do all set-up on a fresh clone:
#   make run   installs what is missing, builds, serves on 127.0.0.1:8080 with data in ./data
#   make test  installs what is missing (and the test tools), runs the whole test suite
# One cargo profile (release) throughout, so libtorch's torch-sys is compiled once.
SHELL := /bin/bash
export PATH := $(HOME)/.cargo/bin:$(PATH)

.PHONY: run test setup setup-test build bench

run: build
	./target/release/choreo serve --bind 127.0.0.1:8080 --data-dir ./data

test: setup-test
	cargo test --release

setup:
	bash scripts/setup.sh

setup-test:
	bash scripts/setup.sh --test

build: setup
	cargo build --release

# Not a test: GET /v1/jobs/{id} throughput and p99 while the workers are busy.
bench: build
	./target/release/choreo bench http --seconds 10
