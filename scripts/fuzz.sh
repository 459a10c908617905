#!/usr/bin/env bash
# `make fuzz`: fuzzes the table parser past the CRC (core/fuzz, target parse_crc) from a corpus seeded with real
# tables, then tallies which TableError kinds the corpus reaches; then the relight-script parser, the scene
# loader and its glTF path (host/fuzz, targets script, scene and gltf) from the bundled scripts and scenes. Not
# part of `make test`.
#
# Needs a nightly toolchain and cargo-fuzz; installs cargo-fuzz from crates.io if missing, and nightly through
# rustup if missing. FUZZ_RUNS (default 10,000,000) executions of the table target, FUZZ_AUX_RUNS (default
# 1,000,000) of each of the other three; the corpora grow under out/fuzz/ (not committed). Inputs that once
# crashed a target stay in host/fuzz/regressions/TARGET/ (committed; host/tests/gltf.rs replays the glTF ones).
set -euo pipefail
cd "$(dirname "$0")/.."
runs="${FUZZ_RUNS:-10000000}"
aux_runs="${FUZZ_AUX_RUNS:-1000000}"
step() { printf '\n==> fuzz: %s\n' "$1"; }

if ! rustup toolchain list | grep -q '^nightly'; then
    step "nightly toolchain (rustup)"
    rustup toolchain install nightly --profile minimal
fi
if ! command -v cargo-fuzz > /dev/null; then
    step "cargo-fuzz (crates.io)"
    cargo install cargo-fuzz --locked
fi

step "seed tables (radiosity bake on the bundled scenes)"
cargo build --release --locked -q -p radiosity-host --bin radiosity
bin=$(cargo metadata --format-version 1 --no-deps | python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')/release/radiosity
seeds=out/fuzz/seeds
corpus=out/fuzz/parse_crc
mkdir -p "$seeds" "$corpus"
bake() {
    local name=$1
    shift
    "$bin" bake "$@" -o "$seeds/$name.rft" > /dev/null
    printf '  %-28s %7d bytes\n' "$name" "$(stat -c %s "$seeds/$name.rft")"
}
# One patch per face keeps the seeds small (a few KiB), so mutations are cheap; between them they cover both
# code widths, the transfer basis, a solved base with partial run-time state (two-rooms: room B is static) and
# the closed furnace.
bake cornell-16 scenes/cornell-box.obj --no-subdivide
bake cornell-8 scenes/cornell-box.obj --no-subdivide --bits 8
bake cornell-transfer scenes/cornell-box.obj --no-subdivide --transfer
bake two-rooms-partial-state scenes/two-rooms.obj --no-subdivide
bake two-rooms-transfer-8 scenes/two-rooms.obj --no-subdivide --transfer --bits 8
bake furnace scenes/furnace.obj --no-subdivide
bake facing-squares scenes/facing-squares.obj --no-subdivide

step "fuzz parse_crc: $runs executions"
(cd core/fuzz && cargo +nightly fuzz run parse_crc "../../$corpus" "../../$seeds" -- \
    -runs="$runs" -max_len=65536 -print_final_stats=1)

step "what the corpus reaches (tally)"
(cd core/fuzz && cargo +nightly run --release -q --bin tally -- "../../$corpus" "../../$seeds")

step "seed scripts and scenes"
mkdir -p out/fuzz/script-seeds out/fuzz/script out/fuzz/scene-seeds out/fuzz/scene
cp scenes/*.relight.toml out/fuzz/script-seeds/
# A scene input is OBJ, MTL and TOML joined by the target's separator line; the OBJ's mtllib names scene.mtl.
for obj in scenes/*.obj; do
    stem=${obj%.obj}
    mtl=$(sed -n 's/^mtllib \(.*\)$/\1/p' "$obj" | head -n 1)
    {
        sed 's/^mtllib .*$/mtllib scene.mtl/' "$obj"
        printf '\n%%%%%%%%\n'
        [ -n "$mtl" ] && cat "scenes/$mtl"
        if [ -f "$stem.toml" ]; then
            printf '\n%%%%%%%%\n'
            cat "$stem.toml"
        fi
    } > "out/fuzz/scene-seeds/$(basename "$stem")"
done

step "fuzz the relight-script parser: $aux_runs executions"
(cd host/fuzz && cargo +nightly fuzz run script ../../out/fuzz/script ../../out/fuzz/script-seeds -- \
    -runs="$aux_runs" -max_len=16384 -print_final_stats=1)

step "fuzz the scene loader: $aux_runs executions"
(cd host/fuzz && cargo +nightly fuzz run scene ../../out/fuzz/scene ../../out/fuzz/scene-seeds -- \
    -runs="$aux_runs" -max_len=65536 -print_final_stats=1)

step "seed glTF files"
mkdir -p out/fuzz/gltf-seeds out/fuzz/gltf
cp scenes/*.glb out/fuzz/gltf-seeds/
if compgen -G 'host/fuzz/regressions/gltf/*' > /dev/null; then
    cp host/fuzz/regressions/gltf/* out/fuzz/gltf-seeds/
fi
# The JSON form of each .glb, its buffer as a base64 data URI (the target writes one file: no .bin beside it).
for glb in scenes/*.glb; do
    python3 - "$glb" "out/fuzz/gltf-seeds/$(basename "${glb%.glb}").gltf" << 'PY'
import base64, json, struct, sys
data = open(sys.argv[1], "rb").read()
n = struct.unpack_from("<I", data, 12)[0]
doc = json.loads(data[20:20 + n])
m = struct.unpack_from("<I", data, 20 + n)[0]
doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data[28 + n:28 + n + m]).decode()
open(sys.argv[2], "w").write(json.dumps(doc))
PY
done

step "fuzz the glTF loader: $aux_runs executions"
(cd host/fuzz && cargo +nightly fuzz run gltf ../../out/fuzz/gltf ../../out/fuzz/gltf-seeds -- \
    -runs="$aux_runs" -max_len=65536 -print_final_stats=1)
