# The two commands a newcomer needs: `make demo` and `make test`. Both install what they need first (`make deps`).
SHELL := /bin/bash
CARGO ?= cargo

.PHONY: deps demo test bench fuzz fmt-check clippy unit-tests embedded-builds

deps:
	@bash scripts/deps.sh

demo: deps
	$(CARGO) run --release -p radiosity-host --bin radiosity -- demo

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
