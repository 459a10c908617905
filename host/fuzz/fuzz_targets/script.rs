//! Fuzz target: relight-script bytes through `ScriptFile::parse`; accepted files run through the host simulator
//! on a small synthetic table (`radiosity_host_fuzz::script`). Seeded by `scripts/fuzz.sh`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| radiosity_host_fuzz::script(data));
