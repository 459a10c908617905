//! Host-side checks of the device loop: the committed table, the analytic answer of the uniform enclosure,
//! no allocation in the device loop, and a comparison that catches a single flipped bit.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use firmware_sim::device::{self, Frame, NoMeter, Script};
use firmware_sim::qemu::{self, QemuLog};
use firmware_sim::script::{ScriptFile, TableGroups};
use firmware_sim::sim::{self, Arith};
use firmware_sim::synthetic;
use radiosity_core::OwnedBuffers;
use radiosity_core::{Fixed, Scalar, Table};

/// Counts allocations made by the current thread (tests run on several threads).
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

#[allow(unsafe_code)] // A global allocator is an unsafe trait; this one only counts and forwards to System.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn committed_table() -> Vec<u8> {
    std::fs::read(root().join("firmware-sim/tables/uniform-enclosure.rft")).unwrap()
}

#[test]
fn committed_table_is_the_generators_output() {
    assert!(
        committed_table() == synthetic::default_table().unwrap(),
        "firmware-sim/tables/uniform-enclosure.rft is stale: regenerate it with \
         `cargo run -p firmware-sim -- gen-table firmware-sim/tables/uniform-enclosure.rft`"
    );
}

/// The uniform enclosure's exact answer: `B_i = E_i + rho_i / (n - 1) * sum_{j != i} B_j`, solved in f64 by
/// Gauss-Seidel to convergence (the iteration matrix has row sums `<= 0.73`).
fn analytic(n: usize, per_wall: usize) -> Vec<[f64; 3]> {
    let rho = |i: usize| synthetic::MATERIALS[[1, 2, 0, 0, 0, 0][i / per_wall]].map(f64::from);
    let e = |i: usize| {
        if i >= 5 * per_wall && i < 5 * per_wall + synthetic::LIGHT_PATCHES as usize {
            synthetic::LIGHT_EMISSION.map(f64::from)
        } else {
            [0.0; 3]
        }
    };
    let mut b = vec![[0.0f64; 3]; n];
    for _ in 0..200 {
        for i in 0..n {
            let next: [f64; 3] = [0, 1, 2].map(|c| {
                let others: f64 = (0..n).filter(|&j| j != i).map(|j| b[j][c]).sum();
                e(i)[c] + rho(i)[c] * others / (n - 1) as f64
            });
            b[i] = next;
        }
    }
    b
}

fn boot_and_compare<S: Scalar + device::Bits>() -> f64 {
    let bytes = committed_table();
    let table = Table::parse(&bytes).unwrap();
    let n = table.patch_count() as usize;
    let exact = analytic(n, n / 6);
    let mut memory = OwnedBuffers::<S>::for_table(&table);
    let initial = [[1.0f32; 3]];
    let frames = [Frame { budget: 1, intensity: &initial }];
    // Relative tolerance 1e-6 of the light's power: the truncation error is far below the quantization error,
    // and the tolerance is above fixed point's convergence floor for this table (4.9e-7 power units, 3.8e-7 of
    // the light's power; the solver refuses anything below it).
    let script =
        Script { name: "boot", tolerance: 1e-6, initial: &initial, boot_budget: 10_000_000, frames: &frames };
    let mut worst = 0.0f64;
    device::run_script(&table, memory.buffers(), &script, &mut NoMeter, |_, solver| {
        for (i, ex) in exact.iter().enumerate() {
            let b = solver.radiosity(i as u32).unwrap();
            for c in 0..3 {
                worst = worst.max((f64::from(b[c].to_f32()) - ex[c]).abs() / ex[c]);
            }
        }
    })
    .unwrap();
    worst
}

// Error budget (core's crate docs, "Error bounds"): emission codes are within 2^-11 relative; form factors
// (FLOAT16, all entries of a row equal, so each is its row's max) within 2^-12 relative, which the
// interreflection amplifies by at most rho / (1 - rho) = 0.73 / 0.27 < 2.71; reflectance codes within 2^-17
// absolute, amplified likewise by 1 / (1 - rho) < 3.71. Total < 2^-11 + 2.71 * 2^-12 + 3.71 * 2^-17 = 1.16e-3.
const ANALYTIC_TOLERANCE: f64 = 1.16e-3;

#[test]
fn uniform_enclosure_matches_its_analytic_answer_in_f32_and_fixed_point() {
    let f = boot_and_compare::<f32>();
    let x = boot_and_compare::<Fixed>();
    eprintln!("worst relative error against the analytic answer: f32 {f:e}, fixed point {x:e}");
    assert!(f < ANALYTIC_TOLERANCE, "f32: worst relative error {f:e} > {ANALYTIC_TOLERANCE:e}");
    assert!(x < ANALYTIC_TOLERANCE, "fixed: worst relative error {x:e} > {ANALYTIC_TOLERANCE:e}");
}

#[test]
fn device_loop_allocates_nothing() {
    let bytes = committed_table();
    let table = Table::parse(&bytes).unwrap();
    let file = ScriptFile::load(&root().join("scenes/cornell-box.relight.toml"))
        .and_then(|f| f.resolve(&TableGroups::of(&table)))
        .unwrap();
    let mut memory = OwnedBuffers::<f32>::for_table(&table);
    // The counter sees this thread's allocations (so the check below can fail).
    let before = ALLOCATIONS.with(Cell::get);
    drop(std::hint::black_box(vec![0u8; 16]));
    assert_eq!(ALLOCATIONS.with(Cell::get) - before, 1);
    for s in &file.scripts {
        s.with_view(|script| {
            let before = ALLOCATIONS.with(Cell::get);
            let mut frames = 0;
            device::run_script(&table, memory.buffers(), script, &mut NoMeter, |_, _| frames += 1).unwrap();
            let after = ALLOCATIONS.with(Cell::get);
            assert_eq!(after - before, 0, "script {}: the device loop allocated", script.name);
            assert_eq!(frames, script.frames.len());
        });
    }
}

#[test]
fn comparison_catches_one_flipped_bit_and_a_missing_frame() {
    let bytes = committed_table();
    let table = Table::parse(&bytes).unwrap();
    let file = ScriptFile::load(&root().join("scenes/cornell-box.relight.toml"))
        .and_then(|f| f.resolve(&TableGroups::of(&table)))
        .unwrap();
    let host = sim::simulate_file(Arith::Fixed, &table, &file, Some("flicker"), None).unwrap();
    let text: String = host[0].trace.iter().map(|l| format!("{l}\nB,fixed,flicker,0\n")).collect();
    let log = QemuLog::parse(&format!("{text}DONE,0\n")).unwrap();
    assert_eq!(qemu::compare(&host, &log).unwrap(), host[0].trace.len());

    // Flip the lowest bit of the radiosity hash of frame 3.
    let mut bad = log.clone();
    let key = &mut bad.frames[3].key;
    let last = key.pop().unwrap();
    key.push(if last == '0' { '1' } else { '0' });
    assert!(qemu::compare(&host, &bad).unwrap_err().contains("frame line 3 differs"));

    let mut short = log.clone();
    short.frames.pop();
    assert!(qemu::compare(&host, &short).is_err());
}
