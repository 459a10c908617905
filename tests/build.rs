//! Records an rpath to the Embree 4 shared libraries (as `host/build.rs` does for its own targets), so the
//! end-to-end tests that run the host pipeline load Embree without `LD_LIBRARY_PATH`.

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let default_dir = manifest.join("..").join("third_party").join("embree").join("lib");
    let dir = std::env::var_os("RADIOSITY_EMBREE_LIB").map(PathBuf::from).unwrap_or(default_dir);
    println!("cargo:rerun-if-env-changed=RADIOSITY_EMBREE_LIB");
    // radiosity-host's build script fails with a clear message when Embree is missing; here it is only linked.
    if let Ok(dir) = dir.canonicalize() {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
    }
}
