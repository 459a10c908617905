//! Fuzz target: glTF bytes (binary `.glb` or JSON `.gltf`) through the scene loader (`radiosity_host_fuzz::gltf`).
//! Seeded by `scripts/fuzz.sh` with the bundled `scenes/cornell-box.glb` and small `.glb` and `.gltf` files
//! (`host/fuzz/seeds/gltf/`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| radiosity_host_fuzz::gltf(data));
