//! Host-side checks of the device loop: the committed tables, the analytic answer of the uniform enclosure,
//! the hierarchical enclosure's answer against its own linear system, budgets per frame, no allocation in
//! the device loop, and a comparison that catches a single flipped bit.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use firmware_sim::device::{self, Frame, NoMeter, Script};
use firmware_sim::qemu::{self, QemuLog};
use firmware_sim::script::{ScriptFile, TableGroups};
use firmware_sim::sim::{self, Arith};
use firmware_sim::synthetic;
use radiosity_core::{Fixed, Frac, HierOwnedBuffers, HierSolver, HierTable, OwnedBuffers, Scalar, Table};

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

fn committed_hierarchical_table() -> Vec<u8> {
    std::fs::read(root().join("firmware-sim/tables/hierarchical-enclosure.rft")).unwrap()
}

#[test]
fn committed_hierarchical_table_is_the_generators_output() {
    assert!(
        committed_hierarchical_table() == synthetic::default_hierarchical_table().unwrap(),
        "firmware-sim/tables/hierarchical-enclosure.rft is stale: regenerate it with \
         `cargo run -p firmware-sim -- gen-table --hierarchical firmware-sim/tables/hierarchical-enclosure.rft`"
    );
}

#[test]
fn hierarchical_table_has_links_at_three_levels_and_closed_chains() {
    let bytes = committed_hierarchical_table();
    let table = HierTable::parse(&bytes).unwrap();
    assert_eq!((table.node_count(), table.leaf_count()), (42, 24));
    // Senders and receivers at the face (depth 0), half (1) and leaf (2) levels.
    let depth = |mut n: u32| {
        let mut d = 0;
        while let Some(p) = table.parent(n) {
            n = p;
            d += 1;
        }
        d
    };
    let mut levels = std::collections::BTreeSet::new();
    for s in 0..table.node_count() {
        for k in table.run(s).unwrap() {
            let (r, _) = table.link(s, k).unwrap();
            levels.insert((depth(s), depth(r)));
        }
    }
    assert_eq!(levels.into_iter().collect::<Vec<_>>(), [(0, 0), (1, 1), (2, 2)]);
    // Every leaf's chain sums to 1 within the form-factor codec's rounding (FLOAT16: 2^-11 relative per
    // entry, at most 8 entries per run, 3 runs per chain).
    for l in 0..table.leaf_count() {
        let mut n = Some(table.leaf_node(l).unwrap());
        let mut sum = 0.0f64;
        while let Some(node) = n {
            sum += f64::from(table.run_sum(node).unwrap());
            n = table.parent(node);
        }
        assert!(sum <= 1.0 && sum > 1.0 - 24.0 * 2f64.powi(-11), "leaf {l}: chain sum {sum}");
    }
}

fn frac(f: Frac) -> f64 {
    f64::from(f.mantissa) * 2f64.powi(-(f.shift as i32))
}

/// The hierarchical table's own linear system (core's `hier` module docs), from the table's decoded numbers,
/// in f64, independently of the solver: `B_l = E_l + rho_l sum_{r in chain(l)} (1 / A_r) sum_s F_sr Phi_s`,
/// `Phi_s = sum of A_l' B_l'` over the leaves below sender `s`, with every light group at `intensity`.
/// Jacobi iteration until nothing changes in f64 (the iteration contracts by `rho_max <= 0.73` per step).
fn hierarchical_system(table: &HierTable<'_>, intensity: f64) -> Vec<[f64; 3]> {
    let leaves = table.leaf_count() as usize;
    let area: Vec<f64> = (0..table.leaf_count()).map(|l| f64::from(table.leaf_area(l).unwrap())).collect();
    let rho: Vec<[f64; 3]> = (0..table.leaf_count())
        .map(|l| {
            let code = table.reflectance(table.material(l).unwrap()).unwrap();
            code.map(|c| frac(radiosity_core::codec::decode_reflectance(c)))
        })
        .collect();
    let mut emission = vec![[0.0f64; 3]; leaves];
    for g in 0..table.group_count() {
        for k in table.group_members(g).unwrap() {
            let m = table.member(k).unwrap();
            for (e, m) in emission[m.leaf as usize].iter_mut().zip(m.emission) {
                *e += intensity * f64::from(m);
            }
        }
    }
    let mut b = emission.clone();
    for _ in 0..1000 {
        // Power of every node's subtree, then the irradiance every node's links deliver.
        let phi: Vec<[f64; 3]> = (0..table.node_count())
            .map(|n| {
                let mut p = [0.0; 3];
                for l in table.leaf_range(n).unwrap() {
                    for c in 0..3 {
                        p[c] += area[l as usize] * b[l as usize][c];
                    }
                }
                p
            })
            .collect();
        let mut irradiance = vec![[0.0f64; 3]; table.node_count() as usize];
        for s in 0..table.node_count() {
            for k in table.run(s).unwrap() {
                let (r, f) = table.link(s, k).unwrap();
                let a_r = f64::from(table.node_area(r).unwrap());
                for c in 0..3 {
                    irradiance[r as usize][c] += frac(f) * phi[s as usize][c] / a_r;
                }
            }
        }
        let next: Vec<[f64; 3]> = (0..table.leaf_count())
            .map(|l| {
                let mut e = [0.0; 3];
                let mut n = Some(table.leaf_node(l).unwrap());
                while let Some(node) = n {
                    for c in 0..3 {
                        e[c] += irradiance[node as usize][c];
                    }
                    n = table.parent(node);
                }
                [0, 1, 2].map(|c| emission[l as usize][c] + rho[l as usize][c] * e[c])
            })
            .collect();
        if next == b {
            break;
        }
        b = next;
    }
    b
}

/// The device (host simulator, f32) boots the hierarchical enclosure to convergence and agrees with the
/// table's own system ([`hierarchical_system`]) within a bound derived from f32 rounding and the tolerance.
#[test]
fn hierarchical_enclosure_converges_to_its_own_system() {
    let bytes = committed_hierarchical_table();
    let table = HierTable::parse(&bytes).unwrap();
    let exact = hierarchical_system(&table, 1.0);
    let mut memory = HierOwnedBuffers::<f32>::for_table(&table);
    let initial = [[1.0f32; 3]];
    let frames = [Frame { budget: 1, intensity: &initial }];
    let tolerance = 1e-7f32;
    let script =
        Script { name: "boot", tolerance, initial: &initial, boot_budget: 10_000_000, frames: &frames };
    let (mut worst, mut bound_used) = (0.0f64, 0.0f64);
    let mut checked = 0;
    device::run_script(&table, memory.buffers(), &script, &mut NoMeter, |r, solver: &HierSolver<'_, f32>| {
        assert!(r.converged(), "{r:?}");
        // Rounding: each bounce's path from a sender's unshot power to a leaf's power rounds at most
        // 6 + 2 D times (shot F U, division by A_r, D pending additions down the chain, times A_l, times
        // rho, the addition to the leaf's power; D pull additions back up into the unshot power), and a
        // leaf's power and a node's unshot power each accumulate at most one addition per sweep; with
        // overshoot (`Config::RECOMMENDED_OVERSHOOT`, 1/4) the terms of those sums have magnitudes at most
        // 1 + 2/4 times their sum. Each bounce's relative error carries over to the next scaled by rho, so
        // the relative error is at most `k u / (1 - rho_max)` with `k = 1.5 (6 + 2 D + 2 sweeps)`,
        // `u = 2^-24`.
        let d = f64::from(table.max_depth());
        let k = 1.5 * (6.0 + 2.0 * d + 2.0 * f64::from(solver.sweeps()));
        let rho_max = 0.73;
        let relative = k * 2f64.powi(-24) / (1.0 - rho_max);
        // Truncation: every linked node's unshot magnitude is at most the tolerance (absolute: tolerance
        // times the unit light power) and nothing is pending; shot, that power raises a leaf's radiosity by
        // at most rho_max / (1 - rho_max) times it over the smallest leaf area (chains sum to at most 1).
        let linked = (0..table.node_count()).filter(|&n| table.has_links(n)).count() as f64;
        let tau = f64::from(tolerance) * f64::from(device::hier_unit_light_power(&table));
        let a_min =
            (0..table.leaf_count()).map(|l| f64::from(table.leaf_area(l).unwrap())).fold(f64::MAX, f64::min);
        let truncation = linked * tau * rho_max / (1.0 - rho_max) / a_min;
        for (l, ex) in exact.iter().enumerate() {
            let b = solver.radiosity(l as u32).unwrap();
            for c in 0..3 {
                let err = (f64::from(b[c]) - ex[c]).abs();
                let allowed = relative * ex[c] + truncation;
                assert!(
                    err <= allowed,
                    "leaf {l} channel {c}: device {} exact {} error {err:e} > {allowed:e}",
                    b[c],
                    ex[c]
                );
                worst = worst.max(err / ex[c]);
                bound_used = bound_used.max(err / allowed);
                checked += 1;
            }
        }
    })
    .unwrap();
    assert_eq!(checked, 3 * 24);
    eprintln!(
        "hierarchical enclosure: worst relative error {worst:e}, largest share of the bound {bound_used:.3}"
    );
}

/// Every frame of every shipped script on the hierarchical table spends at most its budget, in f32 and fixed
/// point, and some frames spend all of it (so the check bites).
#[test]
fn hierarchical_frames_respect_their_budgets() {
    fn check<S: device::Bits>(table: &HierTable<'_>, file: &ScriptFile) {
        let mut memory = HierOwnedBuffers::<S>::for_table(table);
        let mut full = 0;
        for s in &file.scripts {
            s.with_view(|script| {
                device::run_script(table, memory.buffers(), script, &mut NoMeter, |r, _| {
                    assert!(
                        r.used <= r.budget,
                        "{}: frame {} used {} > budget {}",
                        script.name,
                        r.frame,
                        r.used,
                        r.budget
                    );
                    full += usize::from(r.used == r.budget);
                })
                .unwrap();
            });
        }
        assert!(full > 0, "{}: no frame used its whole budget", S::NAME);
    }
    let bytes = committed_hierarchical_table();
    let table = HierTable::parse(&bytes).unwrap();
    let file = ScriptFile::load(&root().join("scenes/cornell-box.relight.toml"))
        .and_then(|f| f.resolve(&TableGroups::of(&table)))
        .unwrap();
    check::<f32>(&table, &file);
    check::<Fixed>(&table, &file);
}

#[test]
fn committed_four_lights_table_is_the_generators_output() {
    let committed = std::fs::read(root().join("firmware-sim/tables/four-lights.rft")).unwrap();
    assert!(
        committed == synthetic::four_lights_table().unwrap(),
        "firmware-sim/tables/four-lights.rft is stale: regenerate it with \
         `cargo run -p firmware-sim -- gen-table --four-lights firmware-sim/tables/four-lights.rft`"
    );
    // Its scripts resolve against it by the groups' names.
    let table = Table::parse(&committed).unwrap();
    assert_eq!(table.group_count(), synthetic::FOUR_LIGHTS);
    ScriptFile::load(&root().join("firmware-sim/tables/four-lights.relight.toml"))
        .and_then(|f| f.resolve(&TableGroups::of(&table)))
        .unwrap();
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
    let bytes = committed_hierarchical_table();
    let table = HierTable::parse(&bytes).unwrap();
    let mut memory = HierOwnedBuffers::<f32>::for_table(&table);
    for s in &file.scripts {
        s.with_view(|script| {
            let before = ALLOCATIONS.with(Cell::get);
            device::run_script(&table, memory.buffers(), script, &mut NoMeter, |_, _| {}).unwrap();
            let after = ALLOCATIONS.with(Cell::get);
            assert_eq!(after - before, 0, "hierarchical, script {}: the device loop allocated", script.name);
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
    let host = sim::simulate_file(Arith::Fixed, table, &file, Some("flicker"), None).unwrap();
    let text: String = host[0].trace.iter().map(|l| format!("{l}\nB,fixed,flicker,0\n")).collect();
    let transfers: String = host[0].transfer.iter().map(|l| format!("{l}\n")).collect();
    let log = QemuLog::parse(&format!("{text}{transfers}DONE,0\n")).unwrap();
    assert!(!host[0].transfer.is_empty(), "the committed table carries a transfer basis");
    assert_eq!(qemu::compare(&host, &log).unwrap(), (host[0].trace.len(), host[0].transfer.len()));

    // A transfer relight's hash with one bit flipped, and a missing one.
    let mut bad = log.clone();
    let key = &mut bad.transfers[1].key;
    let last = key.pop().unwrap();
    key.push(if last == '0' { '1' } else { '0' });
    assert!(qemu::compare(&host, &bad).unwrap_err().contains("transfer relight line 1 differs"));
    let mut short = log.clone();
    short.transfers.pop();
    assert!(qemu::compare(&host, &short).unwrap_err().contains("transfer relight"));

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

/// Per channel, `|relit - exact| <= 2^-13 |exact| + 2^-27 T_max` (the transfer codes' rounding: half a step of
/// a 12-bit significand, and the subnormal step under the scale `2^K <= T_max`) plus `ff` times the largest
/// exact value (the form-factor codes' part, 0 where `exact` is the system of the decoded factors) and four f32
/// roundings. Returns the worst ratio of error to bound.
fn transfer_within(relit: &[[f32; 3]], exact: &[[f64; 3]], ff: f64) -> f64 {
    let mut worst = 0.0f64;
    for c in 0..3 {
        let t_max = exact.iter().map(|b| b[c]).fold(0.0, f64::max);
        for (r, e) in relit.iter().zip(exact) {
            let bound = 2f64.powi(-13) * e[c]
                + 2f64.powi(-27) * t_max
                + ff * t_max
                + 4.0 * f64::from(f32::EPSILON) * e[c];
            worst = worst.max((f64::from(r[c]) - e[c]).abs() / bound);
        }
    }
    worst
}

#[test]
fn committed_tables_transfer_bases_relight_to_their_systems() {
    use radiosity_core::relight_transfer;
    // Flat: the analytic answer at unit intensity (the table's 1 / (n - 1) is its f32, relative 2^-24 off).
    let bytes = committed_table();
    let table = Table::parse(&bytes).unwrap();
    let n = table.patch_count() as usize;
    let mut out = vec![[0.0f32; 3]; n];
    relight_transfer(&table, &[[1.0f32; 3]], &mut out).unwrap();
    let worst = transfer_within(&out, &analytic(n, n / 6), 0.0);
    assert!(worst <= 1.0, "flat: worst error at {worst} of the bound");
    // Hierarchical: the system of the table's decoded link factors; the basis was solved with the unquantized
    // factors, each within 2^-11 relative of its code, which moves the answer by at most
    // rho / (1 - rho) 2^-11 of the largest value (rho <= 0.73).
    let bytes = committed_hierarchical_table();
    let table = HierTable::parse(&bytes).unwrap();
    let mut out = vec![[0.0f32; 3]; table.leaf_count() as usize];
    relight_transfer(&table, &[[1.0f32; 3]], &mut out).unwrap();
    let worst = transfer_within(&out, &hierarchical_system(&table, 1.0), 0.73 / 0.27 * 2f64.powi(-11));
    assert!(worst <= 1.0, "hierarchical: worst error at {worst} of the bound");
}
