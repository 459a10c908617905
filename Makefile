# The two commands a newcomer needs: `make demo` and `make test`. Both install what they need first (`make deps`).
# `make demo QEMU=0` skips the Cortex-M4 firmware build and QEMU run (and does not install QEMU, the ARM binutils
# or the embedded Rust targets); the demo's outputs go to out/ (OUT=DIR to change).
SHELL := /bin/bash
CARGO ?= cargo
QEMU ?= 1
OUT ?= out
export QEMU

.PHONY: deps demo web test bench fuzz fmt-check clippy unit-tests embedded-builds

deps:
	@bash scripts/deps.sh

# The demo needs neither Chromium nor the npm packages of the web checks (WEB=0).
demo:
	@WEB=0 bash scripts/deps.sh
	$(CARGO) run --release -p radiosity-host --bin radiosity -- demo --out $(OUT) $(if $(filter 0,$(QEMU)),--no-qemu)

# The browser viewer of the Cornell box in $(OUT)/web: the device core built as WebAssembly (target/web), then
# `radiosity view`. Open it with `python3 -m http.server -d $(OUT)/web` (any static server will do).
web:
	@WEB=0 QEMU=0 WASM=1 bash scripts/deps.sh
	$(CARGO) build --release -p radiosity-web --target wasm32-unknown-unknown --target-dir target/web \
		--config profile.release.debug=0 --config profile.release.strip=true
	$(CARGO) run --release -p radiosity-host --bin radiosity -- view scenes/cornell-box.obj --web $(OUT)/web

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
