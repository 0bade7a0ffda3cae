# envhub's one entry point for dev commands; CI calls `make test` too.
#
#   make demo   a random-policy rollout on the embedded hub (no daemon needed)
#   make test   every check: format, clippy, Rust tests, Python tests
#
# Both set themselves up on a fresh machine: the Python tools go into .venv/ from PyPI.

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help

PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
VENV_STAMP := $(VENV)/.installed
CARGO ?= cargo
# Tests that drive Python (parity with Gymnasium) use the project's interpreter.
export ENVHUB_PYTHON := $(abspath $(VPY))

.PHONY: help demo test lint fmt rust-test py-test build venv clean

help:
	@echo "make demo   run the main job: a rollout on the embedded hub"
	@echo "make test   run every check (fmt, clippy, Rust and Python tests)"
	@echo "make lint   cargo fmt --check and clippy -D warnings"
	@echo "make fmt    format the code"

$(VENV_STAMP): requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --upgrade pip
	$(VPY) -m pip install --quiet -r requirements-dev.txt
	touch $@

venv: $(VENV_STAMP)

build:
	$(CARGO) build --release --workspace --bins

demo: build
	./target/release/envhub match "balance a pole on a cart"
	./target/release/envhub run gym-cartpole --num-envs 64 --steps 1000000
	./target/release/envhub run gym-pendulum --num-envs 8 --steps 200000

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

fmt:
	$(CARGO) fmt --all

rust-test: $(VENV_STAMP)
	# End-to-end tests start the real binaries: build them first.
	$(CARGO) build --workspace --bins
	@if $(CARGO) nextest --version >/dev/null 2>&1; then \
		$(CARGO) nextest run --workspace $${CI:+--profile ci}; \
	else \
		$(CARGO) test --workspace; \
	fi
	$(CARGO) test --workspace --doc

py-test: $(VENV_STAMP)
	$(VPY) -m pytest tests/python -q -p no:cacheprovider

test: lint rust-test py-test

clean:
	$(CARGO) clean
	rm -rf $(VENV)
