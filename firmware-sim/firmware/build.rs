//! Compiles the table and the relight scripts into the firmware.
//!
//! - `RADIOSITY_TABLE` (default `../tables/uniform-enclosure.rft`): the table, `include_bytes!`-ed into flash.
//!   Either format: a flat table (version 3) is parsed here with core's `Table::parse` and core's
//!   `BufferSizes::of` gives the capacities of the solver's `StaticBuffers`; a hierarchical one (version 5,
//!   which `Table::parse` reports as `TableError::HierarchicalTable`) is parsed with `HierTable::parse` and
//!   `HierBufferSizes::of` sizes `HierStaticBuffers`. The generated code names the table type
//!   (`FirmwareTable`) and the buffers (`DeviceBuffers<S>`); the firmware's `main` is the same for both, so a
//!   baked table drops in by changing this one path.
//! - `RADIOSITY_SCRIPTS` (default `../../scenes/cornell-box.relight.toml`): the relight scripts, parsed and
//!   validated with firmware-sim's parser and written out as const data.
//! - The linker memory map follows the target (`firmware_sim::qemu::memory_map`): `memory-mps2-an386.x`
//!   (Cortex-M4, 512 KiB flash / 64 KiB RAM budget) or `memory-microbit.x` (Cortex-M0, 256 KiB / 16 KiB).
use std::path::{Path, PathBuf};

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn path_from_env(var: &str, default: &str, dir: &Path) -> PathBuf {
    println!("cargo:rerun-if-env-changed={var}");
    let p = std::env::var_os(var).map_or_else(|| dir.join(default), PathBuf::from);
    if p.is_absolute() {
        p
    } else {
        dir.join(p)
    }
}

fn run() -> Result<(), String> {
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").map_err(|e| e.to_string())?);
    let out = PathBuf::from(std::env::var("OUT_DIR").map_err(|e| e.to_string())?);
    let table_path = path_from_env("RADIOSITY_TABLE", "../tables/uniform-enclosure.rft", &dir);
    let scripts_path = path_from_env("RADIOSITY_SCRIPTS", "../../scenes/cornell-box.relight.toml", &dir);
    println!("cargo:rerun-if-changed={}", table_path.display());
    println!("cargo:rerun-if-changed={}", scripts_path.display());

    let bytes = std::fs::read(&table_path)
        .map_err(|e| format!("{}: cannot read table: {e}", table_path.display()))?;
    let table =
        firmware_sim::sim::AnyTable::parse(&bytes).map_err(|e| format!("{}: {e}", table_path.display()))?;
    // Scripts that name light groups are resolved by the names' ids (`radiosity_core::group_id`).
    let scripts = firmware_sim::script::ScriptFile::load(&scripts_path).map_err(|e| e.to_string())?;
    let scripts = scripts.resolve(&table.groups()).map_err(|e| format!("{}: {e}", scripts_path.display()))?;

    let mut code = String::new();
    code.push_str(&format!(
        "// Table {} ({} bytes, format version {}), scripts {}.\n",
        table_path.display(),
        bytes.len(),
        table.version(),
        scripts_path.display()
    ));
    code.push_str(&device_types(&table));
    code.push_str(&format!(
        "pub static TABLE: &[u8] = include_bytes!({:?});\n",
        table_path.display().to_string()
    ));
    code.push_str(&scripts.to_rust());
    code.push_str(&format!(
        "/// Light groups of the table (the transfer pass's intensities).\npub const LIGHT_GROUPS: usize = {};\n",
        table.groups().len()
    ));
    // SysTick's clock under QEMU: mps2-an386 25 MHz, microbit (nRF51) 16 MHz. With `-icount shift=0` an
    // instruction takes 1 ns, so a tick is 40 (resp. 62.5 = 125 / 2) instructions.
    let target = std::env::var("TARGET").unwrap_or_default();
    let m0 = target.starts_with("thumbv6m");
    let per_tick = if m0 { (125, 2) } else { (40, 1) };
    // The same choice the host makes when it checks RAM use against the board (`qemu::board_ram`).
    let memory = firmware_sim::qemu::memory_map(&target);
    // A table whose buffers alone exceed the board's RAM is refused here, by name and size, rather than by
    // the linker (`firmware-sim qemu` refuses it before building: `qemu::check_buffers_fit`).
    let arith = if std::env::var_os("CARGO_FEATURE_FIXED").is_some() {
        firmware_sim::sim::Arith::Fixed
    } else {
        firmware_sim::sim::Arith::F32
    };
    let map = std::fs::read_to_string(dir.join(memory)).map_err(|e| format!("{memory}: {e}"))?;
    let ram = firmware_sim::qemu::parse_ram_length(&map).ok_or_else(|| format!("{memory}: no RAM length"))?;
    let buffers = table.buffer_bytes(arith) as u64;
    if buffers > ram {
        return Err(format!(
            "{}: the solver's buffers need {buffers} bytes of RAM in {arith} ({} elements), the board of {target} \
             has {ram} bytes ({memory})",
            table_path.display(),
            table.element_count()
        ));
    }
    code.push_str(&format!(
        "/// Instructions per SysTick tick, as a fraction.\npub const INSTRUCTIONS_PER_TICK: (u64, u64) = {per_tick:?};\n"
    ));
    std::fs::write(out.join("generated.rs"), code).map_err(|e| e.to_string())?;
    std::fs::copy(dir.join(memory), out.join("memory.x")).map_err(|e| format!("{memory}: {e}"))?;
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={memory}");
    println!("cargo:rerun-if-changed=build.rs");
    Ok(())
}

/// The table type and the solver's static buffers for `table`: core's `BufferSizes::of` /
/// `HierBufferSizes::of`, the one place their capacities are derived, written as the const generics of
/// `StaticBuffers` / `HierStaticBuffers` (this is the one place the firmware names those types).
fn device_types(table: &firmware_sim::sim::AnyTable<'_>) -> String {
    use firmware_sim::sim::AnyTable;
    let (table_type, sizes, buffers) = match table {
        AnyTable::Flat(t) => {
            let s = radiosity_core::BufferSizes::of(t);
            let generics = format!("{}, {}, {}, {}", s.slots, s.selection, s.groups, s.materials);
            ("Table", format!("BufferSizes::of: {s:?}"), format!("StaticBuffers<S, {generics}>"))
        }
        AnyTable::Hier(t) => {
            let s = radiosity_core::HierBufferSizes::of(t);
            let generics =
                format!("{}, {}, {}, {}, {}, {}", s.leaves, s.nodes, s.inner, s.depth, s.groups, s.materials);
            ("HierTable", format!("HierBufferSizes::of: {s:?}"), format!("HierStaticBuffers<S, {generics}>"))
        }
    };
    format!(
        "/// The table's format.\n\
         pub type FirmwareTable<'a> = radiosity_core::{table_type}<'a>;\n\
         /// The solver's buffers for this table ({sizes}).\n\
         pub type DeviceBuffers<S> = radiosity_core::{buffers};\n"
    )
}
