//! Points the linker at the Embree 4 shared libraries that `make deps` unpacks into `third_party/embree/lib`,
//! and records an rpath so binaries and tests run without `LD_LIBRARY_PATH`.

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let default_dir = manifest.join("..").join("third_party").join("embree").join("lib");
    let dir = std::env::var_os("RADIOSITY_EMBREE_LIB").map(PathBuf::from).unwrap_or(default_dir);
    println!("cargo:rerun-if-env-changed=RADIOSITY_EMBREE_LIB");
    println!("cargo:rerun-if-changed={}", dir.display());
    if !dir.join("libembree4.so").exists() {
        panic!(
            "Embree 4 not found: {} has no libembree4.so. Run `make deps` at the repository root \
             (it unpacks Embree 4.4.0 from the PyPI wheel embreex==4.4.0.post1), or set RADIOSITY_EMBREE_LIB \
             to a folder holding libembree4.so.",
            dir.display()
        );
    }
    let dir = dir.canonicalize().expect("the Embree folder exists, so it can be canonicalized");
    println!("cargo:rustc-link-search=native={}", dir.display());
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
}
