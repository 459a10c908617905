//! Fuzz target: arbitrary bytes through `Table::parse` and, when accepted, every accessor, bounded solver steps
//! and relighting (`radiosity_core_fuzz::exercise`). Random bytes mostly stop at the magic, header or CRC;
//! `parse_crc` gets past the CRC.
//!
//! Run: `make fuzz` (or `cd core/fuzz && cargo +nightly fuzz run parse`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = radiosity_core_fuzz::exercise(data);
});
