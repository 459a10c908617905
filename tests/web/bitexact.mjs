// Runs a relight script on the WebAssembly build of the device core (radiosity-web) under Node.js, as the host
// simulator's device loop runs it (firmware-sim/src/device.rs: boot, then per frame the light groups whose
// intensity changed and one bounded step), and prints per frame the units used, the outcome and the bits of
// every patch's radiosity, for a bit-for-bit comparison; then the transfer-basis answer for the last intensities.
// Usage: node bitexact.mjs WASM TABLE SCRIPT.json
// SCRIPT.json: { "tolerance": relative, "initial": [[r, g, b], ...], "boot_budget": n,
//                "frames": [{ "budget": n, "intensity": [[r, g, b], ...] }, ...] }
import { readFileSync } from "node:fs";

const [wasmPath, tablePath, scriptPath] = process.argv.slice(2);
if (!wasmPath || !tablePath || !scriptPath) {
    console.error("usage: node bitexact.mjs WASM TABLE SCRIPT.json");
    process.exit(2);
}
const script = JSON.parse(readFileSync(scriptPath, "utf8"));
const { instance } = await WebAssembly.instantiate(readFileSync(wasmPath), {});
const w = instance.exports;
const message = () => new TextDecoder().decode(new Uint8Array(w.memory.buffer, w.rft_message(), w.rft_message_len()));
const table = readFileSync(tablePath);
const at = w.rft_table_buffer(table.length);
new Uint8Array(w.memory.buffer, at, table.length).set(table);
if (w.rft_load(script.tolerance) !== 0) {
    throw new Error(`rft_load: ${message()}`);
}
const n = w.rft_patch_count();

// As device::apply_intensities: only groups whose intensity differs (in f32) are set.
const apply = (intensity) => {
    let units = 0;
    intensity.forEach((rgb, g) => {
        const want = rgb.map(Math.fround);
        if (want.some((v, c) => v !== w.rft_intensity(g, c))) {
            const u = w.rft_set_light(g, ...want);
            if (u < 0) {
                throw new Error(`rft_set_light(${g}): ${message()}`);
            }
            units += u;
        }
    });
    return units;
};
const hex = (x) => x.toString(16);
let radiosityAt = 0;
const bitsAt = (at) => Array.from(new Uint32Array(w.memory.buffer, at, 3 * n), hex);
const bits = () => {
    radiosityAt = w.rft_radiosity();
    return bitsAt(radiosityAt);
};

apply(script.initial);
w.rft_step(script.boot_budget);
if (w.rft_outcome() !== 0) {
    throw new Error("the boot solve did not converge");
}
const frames = script.frames.map((frame) => {
    const light_units = apply(frame.intensity);
    const used = w.rft_step(frame.budget);
    return { used, light_units, outcome: w.rft_outcome(), bits: bits() };
});
// The transfer-basis answer for the last intensities (written into the radiosity buffer), when the table has one.
let transfer = null;
if (w.rft_has_transfer() === 1) {
    const units = w.rft_relight_transfer();
    if (units < 0) {
        throw new Error(`rft_relight_transfer: ${message()}`);
    }
    transfer = { units, bits: bitsAt(radiosityAt) };
}
console.log(JSON.stringify({ patches: n, frames, transfer }));
