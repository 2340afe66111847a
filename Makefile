# The two commands of the README: `make demo` and `make test`.
# Both first install what is missing on a fresh Debian/Ubuntu machine.

SHELL := /bin/bash
# OpenCV with contrib (aruco) and libclang for the opencv and iceoryx2 bindings.
# libusb and libudev for pyrealsense2 (the tests write RealSense recordings with it).
APT_PACKAGES := libopencv-dev libopencv-contrib-dev clang libclang-dev pkg-config systemd libusb-1.0-0 libudev1
CARGO ?= cargo
export CARGO_TERM_COLOR ?= never

.PHONY: demo test bootstrap build lint bench help peers fuzz faults systemd pydeps realsense

help:
	@echo "make demo   install what is missing, build (release), run the simulated mission"
	@echo "make test   install what is missing, then run every check and test"
	@echo "make faults the whole fault matrix (make test flies an eighth of it per run)"
	@echo "make systemd the stack under a live systemd in a container (root)"

bootstrap:
	@missing=""; \
	for p in $(APT_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing system packages:$$missing"; \
	  sudo=""; [ "$$(id -u)" -eq 0 ] || sudo=sudo; \
	  $$sudo apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	fi
	@command -v $(CARGO) >/dev/null || { echo "error: cargo not found: install Rust stable (rustup)"; exit 1; }

build: bootstrap
	$(CARGO) build --release --workspace

# The paper's simulated mission: take off, find the pad on its moving vehicle, track
# it, land on it; then the same with every stage its own OS process. Plots and an MCAP
# recording go to demo-out/.
demo: build
	./target/release/landing run --scenario paper-sim --plot demo-out --record demo-out/paper-sim.mcap
	./target/release/landing run --scenario paper-sim --processes --log-dir demo-out/logs

lint: bootstrap
	@if $(CARGO) fmt --version >/dev/null 2>&1; then $(CARGO) fmt --all -- --check; else echo "rustfmt not installed: format check skipped"; fi
	@if $(CARGO) clippy --version >/dev/null 2>&1; then \
	  $(CARGO) clippy --release --workspace --all-targets -- -D warnings; \
	else echo "clippy not installed: lint skipped"; fi

# Python packages the tests run: pyrealsense2 writes RealSense .bag recordings with
# librealsense's own recorder (older than 2.58, which writes ROS 2 .db3 files only).
pydeps:
	@python3 -c 'import numpy, pyrealsense2' 2>/dev/null || python3 -m pip install --quiet --disable-pip-version-check numpy 'pyrealsense2<2.58'

# The units `cargo test --release --workspace` builds, so that after it in `make test` this
# builds nothing: `cargo build -p sim` (or `--workspace` without the test targets) unifies
# the crates' features differently and rebuilt recorder and everything above it twice,
# 3.5 minutes of CI.
TEST_BUILD := $(CARGO) build --release --workspace --all-targets

test: lint pydeps
	$(CARGO) test --release --workspace
	$(MAKE) --no-print-directory peers
	$(MAKE) --no-print-directory fuzz
	$(MAKE) --no-print-directory realsense

# depth-ingest's `realsense` build (a live RealSense, and recordings played by librealsense
# itself) where librealsense2 is installed and pkg-config finds it (Debian does not
# package it: docs/jetson.md). Last: it relinks target/release/depth-ingest against it.
realsense: pydeps
	@if pkg-config --exists realsense2; then \
	  echo "librealsense2 $$(pkg-config --modversion realsense2): checking depth-ingest's realsense build"; \
	  $(CARGO) test --release -p depth_ingest --features realsense --test process; \
	else \
	  echo "librealsense2 not found by pkg-config: depth-ingest's realsense build is not checked here (docs/jetson.md)"; \
	fi

# Every parser of untrusted input (MAVLink, config, scenario, graph, pad layout,
# calibration, MCAP, camera and depth frames) fuzzed for FUZZ_SECONDS each on stable
# Rust: executions per target are printed; a panic, hang or unbounded allocation fails.
FUZZ_SECONDS ?= 5
fuzz:
	$(TEST_BUILD)
	./target/release/landing-fuzz --seconds $(FUZZ_SECONDS)

# Independent MAVLink peers fly the simulator as they fly PX4 SITL: pymavlink, and
# MAVSDK (PyPI `mavsdk` 4.x, the native library, no server to download); pymavlink
# plays PX4's side of `sim --px4-sitl` (HIL_SENSOR / HIL_ACTUATOR_CONTROLS lockstep). An independent
# reader (PyPI `mcap` and `foxglove-schemas-protobuf`) decodes every channel of a
# recording of each mode, against the schemas Foxglove ships.
peers:
	@python3 -c 'import pymavlink' 2>/dev/null || python3 -m pip install --quiet --disable-pip-version-check pymavlink
	@python3 -c 'import mavsdk, sys; sys.exit(not mavsdk.__version__.startswith("4."))' 2>/dev/null || python3 -m pip install --quiet --disable-pip-version-check 'mavsdk>=4,<5'
	$(TEST_BUILD)
	python3 tests/peers/pymavlink_flight.py target/release/sim
	python3 tests/peers/mavsdk_flight.py target/release/sim
	python3 tests/peers/px4_sitl_peer.py target/release/sim
	@python3 -c 'import mcap, foxglove_schemas_protobuf' 2>/dev/null || python3 -m pip install --quiet --disable-pip-version-check mcap foxglove-schemas-protobuf
	@rm -rf target/peers && mkdir -p target/peers
	./target/release/landing run --scenario indoor-static --record target/peers/lockstep.mcap --raw-images >/dev/null
	python3 tests/peers/foxglove_reader.py target/peers/lockstep.mcap --expect-raw-images
	python3 tests/peers/foxglove_reader.py target/peers/lockstep.truth.mcap
	./target/release/landing run --scenario paper-sim --processes --record target/peers/processes.mcap >/dev/null
	python3 tests/peers/foxglove_reader.py target/peers/processes.mcap
	@rm -rf target/peers

# The whole fault matrix (74 flights, about 33 minutes); make test flies one part of eight of
# it per run (tools/landing/tests/faults.rs).
faults: build
	FAULT_MATRIX=full $(CARGO) test --release -p landing --test faults -- --nocapture

# The stack under a live systemd: systemd as PID 1 of a systemd-nspawn container over an
# overlay of this machine, the units from deploy/install.sh, a stage killed ten times in
# ten seconds, a hung one; needs root (tests/systemd/live.sh, docs/jetson.md).
systemd: build
	@command -v systemd-nspawn >/dev/null || { sudo=""; [ "$$(id -u)" -eq 0 ] || sudo=sudo; $$sudo apt-get install -y -qq --no-install-recommends systemd-container >/dev/null; }
	tests/systemd/live.sh

bench: build
	./target/release/landing bench ipc
	./target/release/landing bench planner
