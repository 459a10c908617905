//! What several host test files share: the bundled scenes and a coarse Cornell box.
#![allow(dead_code)] // each test file uses some of these

pub mod field;
pub mod picture;
pub mod web;

use std::path::{Path, PathBuf};

use radiosity_host::formfactor::FormFactorOptions;
use radiosity_host::pipeline::{prepare, PrepareOptions, Prepared};

/// A scene of the repository's `scenes/` folder.
pub fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name)
}

/// The Cornell box meshed coarsely (patch edge <= 140 mm, at most 400 patches) with few form-factor samples
/// (4 points, 4 rays): the whole preparation takes seconds, for tests about what such a mesh already shows
/// (pictures, quantization bounds), not about form-factor accuracy.
pub fn coarse_cornell() -> Prepared {
    let options = PrepareOptions {
        no_subdivide: false,
        max_patch_edge: Some(140.0),
        max_patches: Some(400),
        repair: true,
        form_factors: FormFactorOptions {
            samples_per_patch: 4,
            rays_per_pair: 4,
            progress: false,
            ..FormFactorOptions::default()
        },
        verbose: false,
    };
    prepare(&scene("cornell-box.obj"), &options).unwrap()
}
