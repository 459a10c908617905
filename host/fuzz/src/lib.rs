//! What the host-side fuzz targets share: the relight-script exercise (parse, then run every accepted script
//! through the device loop on a small synthetic table), the scene exercise (OBJ + MTL + TOML bytes written
//! to a scratch folder and loaded) and the glTF exercise (bytes written as a `.glb` and loaded).

use std::path::PathBuf;
use std::sync::OnceLock;

use firmware_sim::script::{ScriptFile, TableGroups};
use firmware_sim::sim::{self, Arith};
use radiosity_core::{FfCodec, Table};
use radiosity_host::scene::Scene;

/// Separates the OBJ, MTL and TOML parts of a scene input.
pub const PART_SEPARATOR: &[u8] = b"\n%%%%\n";

/// A small synthetic table (a closed box of 6 x 2 x 2 patches, one light group) the accepted scripts run on.
fn table_bytes() -> &'static [u8] {
    static TABLE: OnceLock<Vec<u8>> = OnceLock::new();
    TABLE.get_or_init(|| firmware_sim::synthetic::uniform_enclosure(2, 1.0, FfCodec::FLOAT16).expect("table"))
}

/// Parses `data` as a relight script file (must return, never panic); an accepted file whose scripts fit the
/// synthetic table and a bounded amount of work runs through the host simulator in both arithmetics.
pub fn script(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(file) = ScriptFile::parse(text, "fuzz.toml") else { return };
    // Bound the work: frames times budget (and the boot budget) per script.
    let work: u64 = file
        .scripts
        .iter()
        .map(|s| u64::from(s.boot_budget) + s.frames.iter().map(|f| u64::from(f.budget)).sum::<u64>())
        .sum();
    if work > 2_000_000 {
        return;
    }
    let table = Table::parse(table_bytes()).expect("the synthetic table parses");
    let Ok(file) = file.resolve(&TableGroups::of(&table)) else { return };
    for arith in Arith::ALL {
        let _ = sim::simulate_file(arith, &table, &file, None, None);
    }
}

/// This process's scratch folder for scene inputs (in `/dev/shm` when it exists: the loader reads files).
fn scratch() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base =
            if std::path::Path::new("/dev/shm").is_dir() { "/dev/shm".into() } else { std::env::temp_dir() };
        let dir = base.join(format!("radiosity-fuzz-scene-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch folder");
        dir
    })
}

/// Splits `data` at [`PART_SEPARATOR`] into OBJ, MTL and TOML (missing parts are absent files), writes them as
/// `scene.obj`, `scene.mtl`, `scene.toml` and loads the scene: the loader must return a scene or an error,
/// never panic.
pub fn scene(data: &[u8]) {
    let mut parts = [None, None, None];
    let mut rest = data;
    for part in &mut parts {
        let Some(chunk) = (!rest.is_empty()).then_some(rest) else { break };
        match chunk.windows(PART_SEPARATOR.len()).position(|w| w == PART_SEPARATOR) {
            Some(at) => {
                *part = Some(&chunk[..at]);
                rest = &chunk[at + PART_SEPARATOR.len()..];
            }
            None => {
                *part = Some(chunk);
                rest = &[];
            }
        }
    }
    let dir = scratch();
    for (name, part) in ["scene.obj", "scene.mtl", "scene.toml"].iter().zip(parts) {
        let path = dir.join(name);
        match part {
            Some(bytes) => std::fs::write(&path, bytes).expect("scratch write"),
            None => {
                let _ = std::fs::remove_file(&path);
            }
        }
    }
    let _ = Scene::load(dir.join("scene.obj"));
}

/// Writes `data` as `scene.glb` in this process's scratch folder and loads it (the glTF loader tells binary from
/// JSON glTF by the first bytes, not the extension, so this reaches both), without a `NAME.toml` (light groups
/// by material name): the loader must return a scene or an error, never panic.
pub fn gltf(data: &[u8]) {
    let path = scratch().join("scene.glb");
    std::fs::write(&path, data).expect("scratch write");
    let _ = Scene::load_with_toml(&path, None);
}
