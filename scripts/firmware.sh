#!/usr/bin/env bash
# The firmware check: builds the Cortex-M firmware (f32 and fixed point for the Cortex-M4 on mps2-an386, fixed
# point for the Cortex-M0 on microbit), runs every relight script under QEMU with a timeout, compares every
# frame with the host simulator bit for bit, checks that static RAM plus the stack's high-water mark (measured by
# the firmware) fit the board's RAM, and fits and checks the cost model.
#   scripts/firmware.sh            check (logs and the cost report go to $CARGO_TARGET_DIR/firmware/)
#   scripts/firmware.sh --update   also rewrite the committed firmware-sim/COST.md
# Table and scripts: RADIOSITY_TABLE / RADIOSITY_SCRIPTS (default: the committed synthetic table and
# scenes/cornell-box.relight.toml). The committed hierarchical (format version 5) table,
# firmware-sim/tables/hierarchical-enclosure.rft, is run on all builds as well, and its cost model and
# instructions per link and per node visit are appended to the report. Tables with a transfer basis (all three
# committed ones) are also relit from it; the four-light enclosure (firmware-sim/tables/four-lights.rft, its
# scripts beside it) runs on the Cortex-M4 builds for the transfer relight's cost per light group, and the
# Cornell box as a baked hierarchical table (firmware-sim/tables/cornell-box-hier.rft) on m4-f32 for the
# instructions per link and per node visit at a real scene's run lengths; the same scene baked coarser
# (firmware-sim/tables/cornell-box-hier-coarse.rft) on m4-f32 and m4-fixed for fixed point's rates at such lengths.
set -euo pipefail
cd "$(dirname "$0")/.."

command -v qemu-system-arm >/dev/null || {
    echo "error: qemu-system-arm not found: install it with \`make deps\` (scripts/deps.sh)" >&2
    exit 1
}
out="${CARGO_TARGET_DIR:-target}/firmware"
mkdir -p "$out"
args=()
[[ -n "${RADIOSITY_TABLE:-}" ]] && args+=(--table "$RADIOSITY_TABLE")
[[ -n "${RADIOSITY_SCRIPTS:-}" ]] && args+=(--scripts "$RADIOSITY_SCRIPTS")

cargo build --locked -q -p firmware-sim
sim="${CARGO_TARGET_DIR:-target}/debug/firmware-sim"
for target in m4-f32 m4-fixed m0-fixed; do
    echo "--- $target"
    "$sim" qemu "${args[@]}" --target "$target" --timeout 120 --log "$out/$target.log" | tee "$out/$target.txt"
done
# The four-light enclosure (transfer relight with four groups against one: the cost per light group).
lights=(--table firmware-sim/tables/four-lights.rft --scripts firmware-sim/tables/four-lights.relight.toml)
for target in m4-f32 m4-fixed; do
    echo "--- $target (four light groups)"
    "$sim" qemu "${lights[@]}" --target "$target" --timeout 120 --log "$out/four-lights-$target.log" \
        | tee "$out/four-lights-$target.txt"
done
"$sim" cost --log "$out/m4-f32.log" --log "$out/m4-fixed.log" --log "$out/m0-fixed.log" \
    --transfer-log "$out/four-lights-m4-f32.log" --transfer-log "$out/four-lights-m4-fixed.log" \
    --out "$out/COST.md"
{
    printf '\n## Sizes (arm-none-eabi-size) and stack high-water mark (painted stack, scanned under QEMU)\n\n'
    for target in m4-f32 m4-fixed m0-fixed; do
        grep -h '^size:' "$out/$target.txt" | sed "s/^size: /- $target: /"
    done
} >>"$out/COST.md"
hier=firmware-sim/tables/hierarchical-enclosure.rft
hier_args=(--table "$hier")
[[ -n "${RADIOSITY_SCRIPTS:-}" ]] && hier_args+=(--scripts "$RADIOSITY_SCRIPTS")
for target in m4-f32 m4-fixed m0-fixed; do
    echo "--- $target (hierarchical table)"
    "$sim" qemu "${hier_args[@]}" --target "$target" --timeout 120 --log "$out/hier-$target.log" \
        | tee "$out/hier-$target.txt"
done
"$sim" cost "${hier_args[@]}" --log "$out/hier-m4-f32.log" --log "$out/hier-m4-fixed.log" \
    --log "$out/hier-m0-fixed.log" --out "$out/COST-hier.md"
{
    printf '\n# Hierarchical table (format version 5): %s\n' "$hier"
    # The same report for the hierarchical table's logs, its title replaced by the one above.
    tail -n +2 "$out/COST-hier.md" | sed 's/^## /### /'
    printf '\n### Sizes and stack high-water mark\n\n'
    for target in m4-f32 m4-fixed m0-fixed; do
        grep -h '^size:' "$out/hier-$target.txt" | sed "s/^size: /- $target: /"
    done
} >>"$out/COST.md"
# A baked hierarchical table of representative size (the Cornell box at epsilon 0.02, as `make demo` bakes it):
# its runs are as long as a real scene's, where the test table's hold at most 4 links, so its instructions per
# link and per node visit are the ones a device sees. Its f32 buffers fit the M4's 64 KiB of RAM; fixed point's
# do not.
cornell=firmware-sim/tables/cornell-box-hier.rft
echo "--- m4-f32 (the Cornell box as a hierarchical table)"
"$sim" qemu --table "$cornell" --target m4-f32 --timeout 300 --log "$out/cornell-hier-m4-f32.log" \
    | tee "$out/cornell-hier-m4-f32.txt"
"$sim" cost --table "$cornell" --log "$out/cornell-hier-m4-f32.log" --out "$out/COST-cornell.md"
{
    printf '\n# Hierarchical table of representative size (format version 5): %s\n' "$cornell"
    printf '\nThe Cornell box baked as `make demo` baked it before the hierarchy'"'"'s shaft culling (`radiosity bake scenes/cornell-box.obj --method hierarchical --epsilon 0.02 --transfer`; 1,527 leaves), run on the f32 build.\n'
    tail -n +2 "$out/COST-cornell.md" | sed 's/^## /### /'
    printf '\n### Size and stack high-water mark\n\n'
    grep -h '^size:' "$out/cornell-hier-m4-f32.txt" | sed "s/^size: /- m4-f32: /"
} >>"$out/COST.md"
# The Cornell box baked coarser (epsilon 0.1), whose fixed-point buffers fit the M4's 64 KiB: its runs
# are a real scene's too, so its fixed-point rates (and its f32 rates, on the same frames) are the ones a device
# sees, where the test table's runs of at most 4 links mostly measure each shot's setup. A measurement, not a
# table the device ships: frames over its bound are reported, not failed.
coarse=firmware-sim/tables/cornell-box-hier-coarse.rft
for target in m4-f32 m4-fixed; do
    echo "--- $target (the Cornell box as a coarse hierarchical table)"
    "$sim" qemu --table "$coarse" --target "$target" --timeout 300 --log "$out/coarse-hier-$target.log" \
        | tee "$out/coarse-hier-$target.txt"
done
"$sim" cost --table "$coarse" --log "$out/coarse-hier-m4-f32.log" --log "$out/coarse-hier-m4-fixed.log" \
    --report-over-bound --out "$out/COST-coarse.md"
{
    printf '\n# Hierarchical table of representative size in fixed point (format version 5): %s\n' "$coarse"
    printf '\nThe Cornell box baked coarser (`radiosity bake scenes/cornell-box.obj --method hierarchical --epsilon 0.1`), so that fixed point'"'"'s buffers fit the Cortex-M4'"'"'s RAM, run on the f32 and fixed-point builds. Frames over the bound are reported here, not failed: the device does not ship this table.\n'
    tail -n +2 "$out/COST-coarse.md" | sed 's/^## /### /'
    printf '\n### Sizes and stack high-water mark\n\n'
    for target in m4-f32 m4-fixed; do
        grep -h '^size:' "$out/coarse-hier-$target.txt" | sed "s/^size: /- $target: /"
    done
} >>"$out/COST.md"
cat "$out/COST.md"
if [[ "${1:-}" == "--update" ]]; then
    cp "$out/COST.md" firmware-sim/COST.md
    echo "updated firmware-sim/COST.md"
fi
