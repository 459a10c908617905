//! Fuzz target: like `parse`, but the last four bytes are rewritten to the CRC of the rest before parsing, so a
//! mutated table reaches the header and content validation (and, when it passes, the solver) instead of
//! stopping at the CRC. Seeded with real tables by `scripts/fuzz.sh`.
//!
//! Run: `make fuzz` (or `cd core/fuzz && cargo +nightly fuzz run parse_crc CORPUS`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = radiosity_core_fuzz::exercise(&radiosity_core_fuzz::with_crc(data));
});
