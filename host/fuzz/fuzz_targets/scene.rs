//! Fuzz target: OBJ + MTL + TOML bytes (split at `radiosity_host_fuzz::PART_SEPARATOR`) through the scene loader
//! (`radiosity_host_fuzz::scene`). Seeded by `scripts/fuzz.sh` with the bundled scenes.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| radiosity_host_fuzz::scene(data));
