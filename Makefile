# The two commands a newcomer needs: `make demo` and `make test`. Both install what they need first (`make deps`).
# `make demo QEMU=0` skips the Cortex-M4 firmware build and QEMU run (and does not install QEMU, the ARM binutils
# or the embedded Rust targets); the demo's outputs go to out/ (OUT=DIR to change).
SHELL := /bin/bash
CARGO ?= cargo
QEMU ?= 1
OUT ?= out
export QEMU

.PHONY: deps demo test bench fuzz fmt-check clippy unit-tests embedded-builds

deps:
	@bash scripts/deps.sh

# The demo needs neither Chromium nor the npm packages of the web checks (WEB=0).
demo:
	@WEB=0 bash scripts/deps.sh
	$(CARGO) run --release -p radiosity-host --bin radiosity -- demo --out $(OUT) $(if $(filter 0,$(QEMU)),--no-qemu)

test: deps
	@bash scripts/test.sh

# The full benchmark (release build): bench/REPORT.md, CSV files and plots. `cargo bench -p radiosity-host` runs the
# criterion benchmarks of the hot loops.
bench: deps
	$(CARGO) run --release -p radiosity-host --bin radiosity -- bench --out bench

# Fuzzing (nightly + cargo-fuzz, installed if missing): the table parser past the CRC, from real seed tables.
# FUZZ_RUNS sets the executions (default 10 M). Not part of `make test`.
fuzz: deps
	@bash scripts/fuzz.sh
