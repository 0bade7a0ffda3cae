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
# The MuJoCo adapter links libmujoco 3.17.0, copied from the `mujoco` wheel in .venv/ into
# MUJOCO_LIB_DIR (`.cargo/config.toml` points mujoco-rs there). Every cargo command below
# builds the same feature set, so none of them rebuilds what another built.
MUJOCO_VERSION := 3.17.0
MUJOCO_LIB_DIR := .build/mujoco/lib
MUJOCO_LIB := $(MUJOCO_LIB_DIR)/libmujoco.so.$(MUJOCO_VERSION)
FEATURES := --features envhub-worker/mujoco
# One build serves everything: the binaries, the Python extension (pyo3 told to build an
# extension module for the venv's interpreter, as maturin would) and, in the same release
# profile, the tests. Every cargo command sees the same variables and features, so the
# dependency tree is compiled once (plus clippy's metadata-only check).
export PYO3_PYTHON := $(abspath $(VPY))
export PYO3_BUILD_EXTENSION_MODULE := 1
PROFILE := --release
# No path of the build machine in a binary (wheels and `cargo install`ed binaries run
# elsewhere): panic locations and debug info name the repository's files relative to it and
# crates.io's as `index.crates.io-*/crate-x.y/...` (cargo's `trim-paths` does this but is
# unstable in Rust 1.95). Running cargo by hand without the same RUSTFLAGS rebuilds the tree:
# `eval "$$(make -s env)"` exports what the Makefile does.
CARGO_HOME_DIR := $(or $(CARGO_HOME),$(HOME)/.cargo)
export RUSTFLAGS := --remap-path-prefix=$(CURDIR)/= --remap-path-prefix=$(CARGO_HOME_DIR)/registry/src/= --remap-path-prefix=$(CARGO_HOME_DIR)/git/checkouts/=
# clippy's lints run inside the one build: clippy-driver compiles the workspace's own crates
# (it is rustc plus the lints), so `make lint` builds every target once and fails on any
# warning (scripts/deny_warnings.py) instead of `cargo clippy` checking the whole tree a second
# time (about 4 minutes of a cold `make test` on 2 cores). Without clippy the builds use rustc
# and `make lint` says what to install. CLIPPY_ARGS is set so that every build sees the same.
CLIPPY_DRIVER := $(shell clippy-driver --version >/dev/null 2>&1 && command -v clippy-driver)
ifneq ($(CLIPPY_DRIVER),)
export RUSTC_WORKSPACE_WRAPPER := $(CLIPPY_DRIVER)
endif
export CLIPPY_ARGS :=
# Offscreen rendering without a GPU: Mesa's software EGL (Debian packages).
MESA_PACKAGES := libegl1 libegl-mesa0 libgl1-mesa-dri
MESA_STAMP := .build/mesa.installed
# Opt-in ManiSkill3 (`make maniskill`): SAPIEN needs a Vulkan device even for state
# observations. Without a GPU that is Mesa's CPU driver, lavapipe, and Debian 12's (Mesa 22.3)
# lacks a feature SAPIEN requires, so Mesa 25's is unpacked from bookworm-backports into
# .build/ (the system's Mesa, which MuJoCo's EGL rendering uses, is left alone).
LAVAPIPE_DIR := .build/lavapipe
LAVAPIPE_ICD := $(LAVAPIPE_DIR)/lvp_icd.json
MANISKILL_STAMP := $(VENV)/.maniskill-installed
ifneq ($(wildcard $(LAVAPIPE_ICD)),)
export VK_ICD_FILENAMES ?= $(abspath $(LAVAPIPE_ICD))
endif
# Opt-in LIBERO (`make libero`): an interpreter of its own, since LIBERO needs robosuite 1.4 and
# mujoco<3.9 while .venv/ pins mujoco 3.17 (requirements-libero.txt says what goes in). Its scene
# assets come from the Hugging Face Hub (LIBERO's PyPI packages leave them out). Once `make
# libero` succeeded, `make py-test` runs tests/python/worker/hosted/test_libero.py in it as well.
LIBERO_VENV := .venv-libero
LIBERO_VPY := $(LIBERO_VENV)/bin/python
LIBERO_STAMP := $(LIBERO_VENV)/.installed
# Written by `make libero` once the adapter is available (assets included).
LIBERO_READY := $(LIBERO_VENV)/.ready
LIBERO_PACKAGE := hf-libero==0.1.4
# LeRobot 0.6.1 (CPython 3.12, torch, ~7 GB) in an interpreter of its own, the tests' one
# LeRobot: the recorder tests' loader, the plugin's LeRobot commands, LeRobot's policy server
# (requirements-lerobot.txt says why it is not .venv/). uv, from .venv/, downloads in
# parallel. The 3.12 interpreter: pyenv's or PATH's.
LEROBOT_VENV := .venv-lerobot
LEROBOT_STAMP := $(LEROBOT_VENV)/.installed
PYTHON312 = $(shell for p in $$(pyenv root 2>/dev/null)/versions/3.12*/bin/python3.12 $$(command -v python3.12); do "$$p" -c 'import sys; assert sys.version_info[:2] == (3, 12)' 2>/dev/null && { echo "$$p"; break; }; done)

.PHONY: fuzz help demo test build-all suite-envs lint lint-rust fmt rust-test py-test py-install build venv setup clean bench maniskill libero lerobot wheel env

help:
	@echo "make demo   run the main job: a rollout on the embedded hub"
	@echo "make test   run every check (fmt, clippy, Rust and Python tests)"
	@echo "make check  the quick loop: lint, Rust unit tests, the Python tests that need no suite environment"
	@echo "make lint   layer checks, ruff, mypy (the wire layer), cargo fmt --check, every target built with clippy's lints (warnings denied)"
	@echo "make fmt    format the code"
	@echo "make bench  data-plane figures: hub vs in-process, round trip"
	@echo "make fuzz   coverage-guided fuzzing of the parsers (cargo-fuzz, FUZZ_SECONDS each)"
	@echo "make build-all  every binary, rapier's worker included (make demo builds only what it runs)"
	@echo "make wheel  the Python wheel (module, CLI, workers) in dist/, from the one release build"
	@echo "make maniskill  opt-in: ManiSkill3 + a CPU Vulkan driver (about 5 GB; tests then run it)"
	@echo "make libero  opt-in: LIBERO in .venv-libero + its assets from the Hugging Face Hub (about 7 GB)"
	@echo "make lerobot  LeRobot 0.6.1 in .venv-lerobot: the recorder tests' loader, the plugin's LeRobot commands (about 7 GB; make py-test does it)"

# Packages go in with uv (pinned in requirements-dev.txt; pip brings it in first): it resolves
# fast and links files from its cache (~/.cache/uv) instead of copying them, so a second clone
# of the repo (CI's) installs in seconds and takes almost no disk (torch alone is 6 GB).
UV := $(VENV)/bin/uv
UV_PIP := $(UV) pip install --quiet --python $(VPY)
# The interpreter and uv come first; then the mujoco wheel, whose libmujoco the build needs;
# then the rest, while cargo compiles (`make demo` and `make test` run both at once).
VENV_BASE := $(VENV)/.uv-installed
$(VENV_BASE): requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --disable-pip-version-check "$$(grep -E '^uv==' requirements-dev.txt)"
	touch $@

$(VENV_STAMP): requirements-dev.txt $(MUJOCO_LIB)
	$(UV_PIP) -r requirements-dev.txt
	touch $@

venv: $(VENV_STAMP)

# libmujoco from the wheel, under both names the linker and the loader look for.
$(MUJOCO_LIB): $(VENV_BASE)
	$(UV_PIP) "$$(grep -E '^mujoco==' requirements-dev.txt)"
	mkdir -p $(MUJOCO_LIB_DIR)
	src=$$($(VPY) -c 'import mujoco, os; print(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so.$(MUJOCO_VERSION)"))'); \
	test -f "$$src" || { echo "error: $$src not found; the mujoco wheel should ship it (requirements-dev.txt pins mujoco==$(MUJOCO_VERSION))" >&2; exit 1; }; \
	cp "$$src" $@.tmp && mv $@.tmp $@
	cp $@ $(MUJOCO_LIB_DIR)/libmujoco.so

# Mesa's software EGL for `render_mode="rgb_array"`, installed only where missing. Installing
# needs root (CI runs as root); without it the set-up goes on and says what to install (only
# offscreen rendering needs it, and its error at run time says so too).
$(MESA_STAMP):
	mkdir -p $(dir $@)
	if dpkg -s $(MESA_PACKAGES) >/dev/null 2>&1; then \
		touch $@; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(MESA_PACKAGES) && touch $@; \
	else \
		echo "note: skipped Mesa's software EGL ($(MESA_PACKAGES)): installing it needs root and apt-get;" >&2; \
		echo "      rgb_array rendering without a GPU needs it: sudo apt-get install $(MESA_PACKAGES)" >&2; \
	fi

setup: $(VENV_STAMP) $(MUJOCO_LIB) $(MESA_STAMP)

# Debian's Chromium for the evaluation report's browser test (Playwright drives it; its own
# browser download is not used), installed only where missing and only by root, as Mesa.
BROWSER_STAMP := .build/chromium.installed
$(BROWSER_STAMP): $(MESA_STAMP)
	mkdir -p $(dir $@)
	if command -v chromium >/dev/null; then \
		touch $@; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium && touch $@; \
	else \
		echo "note: skipped Chromium: installing it needs root and apt-get; the report's browser test needs it: sudo apt-get install chromium" >&2; \
	fi

$(MANISKILL_STAMP): $(VENV_STAMP) requirements-maniskill.txt
	$(UV_PIP) -r requirements-maniskill.txt
	touch $@

# lavapipe from bookworm-backports with private apt lists (nothing installed system-wide).
$(LAVAPIPE_ICD):
	. /etc/os-release; test "$${VERSION_CODENAME:-}" = bookworm || { \
		echo "error: the lavapipe recipe is for Debian 12 (bookworm), this is $${PRETTY_NAME:-unknown}" >&2; \
		echo "hint: install a Vulkan driver with descriptorBindingPartiallyBound (Mesa >= 24 lavapipe, or a GPU driver)" >&2; exit 1; }
	rm -rf $(LAVAPIPE_DIR) && mkdir -p $(LAVAPIPE_DIR)/apt/lists/partial $(LAVAPIPE_DIR)/apt/cache/archives/partial $(LAVAPIPE_DIR)/debs
	echo "deb http://deb.debian.org/debian bookworm-backports main" > $(LAVAPIPE_DIR)/apt/sources.list
	apt_opts="-o Dir::Etc::SourceList=$(abspath $(LAVAPIPE_DIR))/apt/sources.list -o Dir::Etc::SourceParts=/dev/null \
		-o Dir::State::Lists=$(abspath $(LAVAPIPE_DIR))/apt/lists -o Dir::Cache=$(abspath $(LAVAPIPE_DIR))/apt/cache"; \
	apt-get -qq $$apt_opts update && cd $(LAVAPIPE_DIR)/debs && apt-get -qq $$apt_opts download mesa-vulkan-drivers/bookworm-backports
	dpkg-deb -x $(LAVAPIPE_DIR)/debs/mesa-vulkan-drivers_*.deb $(LAVAPIPE_DIR)/root
	lib=$(abspath $(LAVAPIPE_DIR))/root/usr/lib/x86_64-linux-gnu/libvulkan_lvp.so; test -f "$$lib"; \
	printf '{"file_format_version": "1.0.0", "ICD": {"library_path": "%s", "api_version": "1.4.305"}}\n' "$$lib" > $@.tmp
	mv $@.tmp $@

maniskill: $(MANISKILL_STAMP) $(LAVAPIPE_ICD)
	VK_ICD_FILENAMES=$(abspath $(LAVAPIPE_ICD)) $(VPY) -c 'import gymnasium as gym, mani_skill.envs; e = gym.make("PickCube-v1", obs_mode="state", sim_backend="cpu", num_envs=1); e.reset(seed=0); e.close(); print("ManiSkill runs: PickCube-v1 on the CPU simulator")'

# hf-libero without its declared dependencies: they add its training stack (wandb,
# transformers, robomimic), which the envs never import.
$(LIBERO_STAMP): requirements-libero.txt
	$(PYTHON) -m venv $(LIBERO_VENV)
	$(LIBERO_VPY) -m pip install --quiet --upgrade pip
	$(LIBERO_VPY) -m pip install --quiet -r requirements-libero.txt
	$(LIBERO_VPY) -m pip install --quiet --no-deps $(LIBERO_PACKAGE)
	touch $@

# The `envhub` package (the one `make py-install` built, same Python version) on its path, the
# assets, then the adapter's verdict as the hub sees it (through ENVHUB_PYTHON).
libero: py-install $(LIBERO_STAMP) $(MESA_STAMP)
	echo "$(abspath python)" > $$($(LIBERO_VPY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/envhub.pth
	$(LIBERO_VPY) -c 'from envhub.worker.hosted.libero import main; raise SystemExit(main(download=True))'
	ENVHUB_PYTHON=$(abspath $(LIBERO_VPY)) ./target/release/envhub adapters --all | grep -E '^(ADAPTER|libero) '
	touch $(LIBERO_READY)

$(LEROBOT_STAMP): requirements-lerobot.txt $(VENV_BASE)
	@test -n "$(PYTHON312)" || { echo "error: LeRobot 0.6.1 needs CPython 3.12: install it (pyenv install 3.12, or uv python install 3.12)" >&2; exit 1; }
	rm -rf $(LEROBOT_VENV)
	$(UV) venv --quiet --python $(PYTHON312) $(LEROBOT_VENV)
	$(UV) pip install --quiet --python $(LEROBOT_VENV)/bin/python -r requirements-lerobot.txt
	touch $@

lerobot: $(LEROBOT_STAMP)

# What the demo and the Python package run: the CLI, the workers and the extension module
# (the tests' build, `make lint`, compiles the rest and reuses these: check_one_build.py;
# rapier's worker is part of the rest: `make build-all`).
# MAKEFLAGS cleared: under `make -j` cargo would take make's job slots (one) for its own.
BUILD_PACKAGES := -p envhub-hub -p envhub-worker -p envhub-python
# The crates (Cargo.lock's pins) are downloaded while .venv/ and libmujoco are set up, which the
# build waits for (mujoco-rs's build script checks the library): 4 s of a fresh machine's demo.
# Those of this machine's platform only (336 MB unpacked, not the lock's 667 MB for every one).
HOST_TRIPLE := $(shell rustc -vV 2>/dev/null | sed -n 's/^host: //p')
CARGO_FETCHED := .build/cargo-fetched
$(CARGO_FETCHED): Cargo.lock
	mkdir -p $(dir $@)
	MAKEFLAGS= $(CARGO) fetch $(if $(HOST_TRIPLE),--target $(HOST_TRIPLE))
	touch $@

build: $(MUJOCO_LIB) $(MESA_STAMP) $(CARGO_FETCHED)
	MAKEFLAGS= $(CARGO) build $(PROFILE) $(BUILD_PACKAGES) $(FEATURES)

# Every binary, rapier's worker (`envhub-worker-rapier`, which `envhub-worker` hands rapier's
# jobs to) included: rapier3d is about a tenth of the release build and the demo runs none of
# it, so `make build` leaves it out (`make test` builds it with the tests).
build-all: build
	MAKEFLAGS= $(CARGO) build $(PROFILE) $(BUILD_PACKAGES) -p envhub-worker-rapier $(FEATURES)

# The build and the Python tools' install at once (one compiles, the other downloads). Each
# rollout is a few seconds: long enough for a steady steps/s (`envhub bench` measures).
demo:
	$(MAKE) --no-print-directory -j2 build venv
	$(MAKE) --no-print-directory py-install
	./target/release/envhub match "balance a pole on a cart"
	./target/release/envhub run gym-cartpole --num-envs 64 --steps 300000
	./target/release/envhub run gym-pendulum --num-envs 8 --steps 100000
	./target/release/envhub run mujoco-ant --num-envs 8 --workers 1 --steps 16000
	$(VPY) python/examples/rollout.py

lint: setup lint-rust
	$(VPY) scripts/check_layers.py
	$(VPY) scripts/check_untested_targets.py
	$(VPY) -m ruff check python tests scripts integrations
	cd python && $(abspath $(VPY)) -m mypy --config-file pyproject.toml --cache-dir $(abspath .build/mypy)

# Every target (tests, benches, examples) built once with clippy's lints, warnings denied: the
# tests reuse the build.
lint-rust: $(MUJOCO_LIB) $(MESA_STAMP)
	$(CARGO) fmt --all -- --check
	$(VPY) scripts/check_one_build.py -- $(PROFILE) $(BUILD_PACKAGES) $(FEATURES)
	@test -n "$(CLIPPY_DRIVER)" || { echo "error: make lint needs clippy: rustup component add clippy" >&2; exit 1; }
	MAKEFLAGS= $(CARGO) build $(PROFILE) --workspace --all-targets $(FEATURES) --message-format=json-diagnostic-rendered-ansi | $(VPY) scripts/deny_warnings.py

fmt:
	$(CARGO) fmt --all

# As root (CI, which installs Chromium), the report's browser test must run, not skip.
BROWSER_REQUIRED := $(shell [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && echo 1)
# As root (CI), the network-namespace tests of hubs across machines must run, not skip.
NETNS_REQUIRED := $(shell [ "$$(id -u)" = 0 ] && command -v ip >/dev/null && command -v unshare >/dev/null && echo 1)
# As root (CI), the tests of another local user against envhub's files (uid 65534) must run.
OTHER_USER_REQUIRED := $(shell [ "$$(id -u)" = 0 ] && echo 1)
# Tests run in the release profile: they reuse `make build`'s compiled tree (dependencies are
# optimised in every profile anyway), and end-to-end tests start the release binaries.
# Two tests per core: most end-to-end tests wait (hubs and workers starting, the bounds they
# time), and the Rust tests took 71 s with one per core, 44 s with two (2 cores, warm).
RUST_TEST_THREADS ?= $(shell echo $$(( $$(nproc) * 2 )))
rust-test: setup py-install
	@if $(CARGO) nextest --version >/dev/null 2>&1; then \
		ENVHUB_PY_REQUIRED=1 ENVHUB_MUJOCO_REQUIRED=1 ENVHUB_PYENV_REQUIRED=1 ENVHUB_NETNS_REQUIRED=$(NETNS_REQUIRED) ENVHUB_OTHER_USER_REQUIRED=$(OTHER_USER_REQUIRED) $(CARGO) nextest run $(PROFILE) --workspace $(FEATURES) --test-threads $(RUST_TEST_THREADS) $${CI:+--profile ci}; \
	else \
		ENVHUB_PY_REQUIRED=1 ENVHUB_MUJOCO_REQUIRED=1 ENVHUB_PYENV_REQUIRED=1 ENVHUB_NETNS_REQUIRED=$(NETNS_REQUIRED) ENVHUB_OTHER_USER_REQUIRED=$(OTHER_USER_REQUIRED) $(CARGO) test $(PROFILE) --workspace $(FEATURES); \
	fi
	$(CARGO) test $(PROFILE) --workspace --doc $(FEATURES)

# The Python package `envhub` into .venv/, editable: the extension module `make build`
# compiled goes next to the pure-Python sources, which a .pth file puts on the venv's path,
# and the release binaries go into its bin/, as in the wheel (`make wheel`).
# envhub-worker-rapier only once built (`make build-all`, `make test`): without it, rapier's
# envs say how to get it.
PY_BINARIES := envhub envhub-worker envhub-worker-mujoco envhub-worker-rapier
PY_SITE = $(shell $(VPY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
# The module is built for the stable ABI (pyo3's `abi3-py39`): one file, `_envhub.abi3.so`,
# loads in every CPython from 3.9 on, the venvs provisioned for suites included (a copy named
# for one interpreter, `_envhub.cpython-311-*.so`, would win over it there and is removed).
PY_EXT_SUFFIX := .abi3.so
py-install: build $(VENV_STAMP)
	rm -f python/envhub/_envhub.cpython-*.so
	cp target/release/lib_envhub.so python/envhub/_envhub$(PY_EXT_SUFFIX).tmp
	mv -f python/envhub/_envhub$(PY_EXT_SUFFIX).tmp python/envhub/_envhub$(PY_EXT_SUFFIX)
	rm -f $(PY_SITE)/envhub.pth $(PY_SITE)/_envhub.pth
	$(VPY) -m pip uninstall --quiet --yes envhub 2>/dev/null || true
	echo "$(abspath python)" > $(PY_SITE)/envhub.pth
	mkdir -p python/envhub/bin
	for b in $(PY_BINARIES); do \
		if [ -f target/release/$$b ]; then \
			cp target/release/$$b python/envhub/bin/$$b.tmp && mv -f python/envhub/bin/$$b.tmp python/envhub/bin/$$b; \
		else rm -f python/envhub/bin/$$b; fi; \
	done

# The wheel: the package, the extension module and the binaries of `make build`, zipped by
# python/build_wheel.py (no second compile, unlike `maturin build`; see the script).
wheel: build-all
	$(VPY) python/build_wheel.py --out dist
	$(VPY) integrations/lerobot/build_wheel.py --out dist

# Python environments for suites (`python_envs:`) are built with uv from requirements-dev.txt
# into the user's cache folder (docs/guide/python-envs.md); uv's own cache stays at its default, so
# a second run installs nothing new. ENVHUB_PYENV_REQUIRED / ENVHUB_SUITES_REQUIRED turn the
# skips of those tests (no uv, no second CPython, no PyPI) into failures.
# The tests mostly wait (hubs, workers, installs): PY_TEST_JOBS of them run side by side
# (pytest-xdist; the isolation rules are in tests/python/README.md). `--dist loadgroup` hands
# out one test at a time, slow ones first (conftest.py). PY_TEST_JOBS=0: one at a time.
# The report's browser test runs afterwards, alone: beside the suites' tests Chromium died at
# its start (SIGTRAP) in CI and in a fresh clone, and never alone. So do the Ray tests (a local
# cluster of their own): beside the suites' tests, in CI, their cluster's GCS went away mid-test.
PY_TEST_JOBS ?= 2
RAY_TESTS := tests/python/evaluation/test_shards_ray.py
py-test: py-install $(LEROBOT_STAMP) $(BROWSER_STAMP)
	ENVHUB_PY_REQUIRED=1 ENVHUB_LEROBOT_REQUIRED=1 ENVHUB_MUJOCO_REQUIRED=1 ENVHUB_PYENV_REQUIRED=1 ENVHUB_SUITES_REQUIRED=1 ENVHUB_RECORD_REQUIRED=1 ENVHUB_BROWSER_REQUIRED=$(BROWSER_REQUIRED) $(VPY) -m pytest tests/python -q -p no:cacheprovider -n $(PY_TEST_JOBS) --dist loadgroup --durations=25 -k "not test_the_report_in_a_browser" --ignore=$(RAY_TESTS)
	ENVHUB_PY_REQUIRED=1 ENVHUB_BROWSER_REQUIRED=$(BROWSER_REQUIRED) $(VPY) -m pytest tests/python/evaluation/test_report.py -q -p no:cacheprovider -k test_the_report_in_a_browser
	ENVHUB_PY_REQUIRED=1 ENVHUB_MUJOCO_REQUIRED=1 $(VPY) -m pytest $(RAY_TESTS) -q -p no:cacheprovider --durations=5
	@if [ -f $(LIBERO_READY) ]; then \
		ENVHUB_PY_REQUIRED=1 ENVHUB_LIBERO_REQUIRED=1 ENVHUB_PYTHON=$(abspath $(LIBERO_VPY)) \
			$(LIBERO_VPY) -m pytest tests/python/worker/hosted/test_libero.py -q -p no:cacheprovider --durations=10; \
	fi

# The suites' Python environments (the catalog's `python_envs:`, LIBERO's 7 GB among them),
# built while the rest of the workspace compiles: mostly downloads and disk writes, which the
# suites' tests would otherwise wait for, one test holding an environment's lock and the other
# test process waiting on it. Not fatal here: a test that needs an environment builds it and
# says why it cannot be (ENVHUB_PYENV_REQUIRED and ENVHUB_SUITES_REQUIRED make that a failure).
# After py-install: an environment gets the `envhub` package of .venv/ on its path.
suite-envs: py-install
	./target/release/envhub env sync || echo "note: envhub env sync failed; the suites' tests say why" >&2

# What the demo builds while the Python tools, LeRobot's loader and Chromium download; then the
# build of every other target while the suites' environments are built; then the checks and
# the tests, one after the other.
test:
	$(MAKE) --no-print-directory -j4 build venv $(LEROBOT_STAMP) $(BROWSER_STAMP)
	$(MAKE) --no-print-directory -j2 lint-rust suite-envs
	$(MAKE) --no-print-directory lint rust-test py-test

# The quick loop (CONTRIBUTING.md): the lint, every crate's unit tests (no integration or
# end-to-end test), and the Python tests that need no suite environment (marked `suite` by
# tests/python/conftest.py from what they use) and take under a minute (`slow`). `make test`
# and CI run everything.
.PHONY: check
check: lint py-install
	@if $(CARGO) nextest --version >/dev/null 2>&1; then \
		ENVHUB_PY_REQUIRED=1 ENVHUB_MUJOCO_REQUIRED=1 $(CARGO) nextest run $(PROFILE) --workspace --lib --bins $(FEATURES) --test-threads $(RUST_TEST_THREADS) $${CI:+--profile ci}; \
	else \
		ENVHUB_PY_REQUIRED=1 ENVHUB_MUJOCO_REQUIRED=1 $(CARGO) test $(PROFILE) --workspace --lib --bins $(FEATURES); \
	fi
	ENVHUB_PY_REQUIRED=1 ENVHUB_MUJOCO_REQUIRED=1 $(VPY) -m pytest tests/python -q -p no:cacheprovider -n $(PY_TEST_JOBS) --dist loadgroup -m "not suite and not slow" --durations=10

# Coverage-guided fuzzing of every parser of another process's bytes (docs/design/fuzzing.md):
# cargo-fuzz (installed if missing), each target FUZZ_SECONDS from its corpus. CI runs it after
# `make test` (.ci/run, 5 s each); not in `make test`, as its AddressSanitizer build of the
# targets takes minutes: `make test` runs the quick tier (crates/hub/src/fuzz.rs) and checks the seed
# corpora (crates/protocol/tests/fuzz_seeds.rs).
FUZZ_SECONDS ?= 10
fuzz:
	scripts/fuzz.sh $(FUZZ_SECONDS)

clean:
	$(CARGO) clean
	rm -rf $(VENV) $(LIBERO_VENV) $(LEROBOT_VENV) .build dist

# The variables cargo sees here, for running it by hand: `eval "$$(make -s env)"`.
env:
	@echo "export PYO3_PYTHON='$(PYO3_PYTHON)' PYO3_BUILD_EXTENSION_MODULE=1 ENVHUB_PYTHON='$(ENVHUB_PYTHON)'"
	@echo "export RUSTFLAGS='$(RUSTFLAGS)'"
	@echo "export RUSTC_WORKSPACE_WRAPPER='$(CLIPPY_DRIVER)' CLIPPY_ARGS="

# Data-plane figures, each line one `envhub bench` run (hub vs in-process in the same run).
BENCH_SECONDS ?= 2
bench: build
	@for n in 1 8 64 256; do for w in 1 2; do \
		if [ $$w -le $$n ]; then ./target/release/envhub bench gym-cartpole --num-envs $$n --workers $$w --seconds $(BENCH_SECONDS) --json; fi; \
	done; done
	@for id in mujoco-ant mujoco-half-cheetah mujoco-humanoid; do \
		./target/release/envhub bench $$id --num-envs 8 --workers 1 --seconds $(BENCH_SECONDS) --json; \
		./target/release/envhub bench $$id --num-envs 16 --workers 2 --seconds $(BENCH_SECONDS) --json; \
	done
