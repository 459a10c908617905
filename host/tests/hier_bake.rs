//! A hierarchical device table baked from the hierarchical solve of the Cornell box, relit by core's
//! hierarchical shooting solver (f32): it converges to the f64 answer of the same links within the error its
//! quantization and arithmetic allow.
//!
//! Bounds from core's crate docs ("Error bounds"): FLOAT16 form factors relative `< 2^-12` (`u`); reflectance
//! absolute `<= 2^-17`; emission and irradiance codes relative `<= 2^-11` (light-group members' emission is
//! stored as f32 in a hierarchical table: relative `2^-24`); f32 additions relative `eps_32 / 2`
//! each.

use radiosity_core::{Config, HierOwnedBuffers, HierSolver, HierTable, Outcome};
use radiosity_host::bake::{bake_hierarchy, BakedHierarchy, HierBakeSummary};
use radiosity_host::hierarchy::{solve_hierarchical, HierarchicalSolution, HierarchyOptions};
use radiosity_host::scene::Scene;

/// The Cornell box and its hierarchical solve at epsilon 0.1 (a few hundred leaves), solved tightly.
fn cornell_box_at_epsilon_0_1() -> (Scene, HierarchicalSolution) {
    let scene = Scene::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/cornell-box.obj")).unwrap();
    let solution = solve_hierarchical(
        &scene,
        &HierarchyOptions { epsilon: 0.1, solve_tolerance: 1e-12, ..HierarchyOptions::default() },
    )
    .unwrap();
    (scene, solution)
}

#[test]
fn cornell_box_hierarchical_table_relights_to_the_f64_answer_of_its_links() {
    let (scene, solution) = cornell_box_at_epsilon_0_1();
    let baked = bake_hierarchy(&scene, &solution, 16, false).unwrap();
    let table = HierTable::parse(&baked.table).unwrap();
    let (nodes, leaves, links) = baked.counts;
    assert_eq!((table.node_count() as usize, table.leaf_count() as usize), (nodes, leaves));
    assert_eq!(table.link_count() as usize, 2 * links, "each link is a run entry at both ends");
    assert!(baked.chain_sum <= 1.0 + 1e-12, "capped chains: {}", baked.chain_sum);
    println!(
        "chain cap: {} leaves over 1 (largest {:.4}), {:.2e} of the power kept back",
        baked.capped.leaves, baked.capped.largest, baked.capped.power_share
    );
    // The cap is a correction of the hierarchy's averages, small against the answer: what it changed is the
    // table system's answer against the hierarchical solve's.
    let (mut moved, mut total) = (0.0, 0.0);
    for (t, b) in baked.radiosity.iter().enumerate() {
        let p = &solution.leaves[baked.solution_leaf[t]];
        moved += p.area * (*b - solution.b[baked.solution_leaf[t]]).abs().max_element();
        total += p.area * b.max_element();
    }
    println!("table system vs hierarchical solve: area-weighted relative difference {:.2e}", moved / total);

    // Converge: the tolerance is a tiny share of the emitted power, so that its term below is negligible.
    let emitted: f64 =
        solution.leaves.iter().zip(&solution.emission).map(|(p, e)| p.area * e.element_sum()).sum();
    let tolerance = 1e-9 * emitted;
    let mut buffers = HierOwnedBuffers::<f32>::for_table(&table);
    let mut solver =
        HierSolver::new(&table, buffers.buffers(), Config { tolerance: tolerance as f32, overshoot: 0 })
            .unwrap();
    let mut steps = 0;
    while !matches!(solver.step(1_000_000), Outcome::Converged { .. }) {
        steps += 1;
        assert!(steps < 10_000, "no convergence after {steps} steps");
    }

    // The bound, in total power `sum_l A_l |B_device - B_f64|` (largest channel), the norm in which the table's
    // shooting system contracts by `q = rho_max * c` (`c` the largest chain sum, at most 1 after the cap): the
    // codes change each shot share by at most `u` relatively (entries in the codec's float range, down to
    // `2^-14` of their run's largest; below it by at most that range's step, `2^-26` of the run's largest, each)
    // and each reflected share by `2^-17` absolutely, the members' f32 emission by `2^-24` (the Cornell box has no
    // static light, whose codes would add `2^-11`); so the fixed points differ by at
    // most `(2^-24 P_E + (u rho_max + 2^-17) c P + 2^-26 L P) / (1 - q)` (`P_E` emitted and `P` total power,
    // `L` the longest run). Converged with at most `tolerance` unshot at each
    // of the `nodes` adds `nodes * tolerance / (1 - q)`. f32 arithmetic, first order in `u = eps_32 / 2`: a unit
    // of power on its way from a sender to a leaf and back into unshot power is rounded at most
    // `K + 2 D + 6 + 2 S` times (`K` the most links into one node: adds into a pending irradiance within a
    // round; `D` the longest chain: the sums down and up a sweep; 6 for the products and the adds into incident
    // power and power; `S` the sweeps, `solver.sweeps()`: the sums of a leaf's power and a node's unshot power
    // over sweeps), so it carries a relative error of at most `u` times that; an error spreads like power, so
    // the total is at most that times `P / (1 - q)`.
    let CodeBound { codes, p_total, q } = code_bound(&solution, &baked, &table);
    let eps32 = f64::from(f32::EPSILON);
    let unshot = nodes as f64 * tolerance / (1.0 - q);
    let mut into = vec![0u32; nodes];
    for s in 0..table.node_count() {
        for k in table.run(s).unwrap() {
            into[table.link(s, k).unwrap().0 as usize] += 1;
        }
    }
    let most_into = f64::from(into.iter().copied().max().unwrap_or(0));
    let roundings = most_into + 2.0 * f64::from(table.max_depth()) + 6.0 + 2.0 * f64::from(solver.sweeps());
    let arithmetic = 0.5 * eps32 * roundings * p_total / (1.0 - q);
    let allowed = codes + unshot + arithmetic;
    let mut worst = 0.0f64;
    let mut error = 0.0;
    for (t, want) in baked.radiosity.iter().enumerate() {
        let got = solver.radiosity(t as u32).unwrap();
        let diff = (0..3).map(|c| (f64::from(got[c]) - want[c]).abs()).fold(0.0, f64::max);
        worst = worst.max(diff / want.max_element());
        error += solution.leaves[baked.solution_leaf[t]].area * diff;
    }
    println!(
        "{leaves} leaves, {links} links, {} bytes ({:.0} per leaf): power error {error:.3e} of {p_total:.3e} \
         (relative {:.2e}; allowed {allowed:.3e}: codes {codes:.1e}, unshot {unshot:.1e}, f32 {arithmetic:.1e}), \
         worst leaf relative {worst:.2e}, {} shots",
        baked.table.len(),
        baked.table.len() as f64 / leaves as f64,
        error / p_total,
        solver.shots()
    );
    assert!(error <= allowed, "device power error {error:.3e} above the allowed {allowed:.3e}");
    assert!(allowed < 0.01 * p_total, "an allowance this large would say nothing");
}

/// What the codes alone may change in the table system's answer, in total power (the derivation is in
/// the test above), with the total power of the f64 answer and the contraction `q = rho_max * c`.
struct CodeBound {
    codes: f64,
    p_total: f64,
    q: f64,
}

fn code_bound(solution: &HierarchicalSolution, baked: &BakedHierarchy, table: &HierTable<'_>) -> CodeBound {
    let u = 2f64.powi(-12);
    let emitted: f64 =
        solution.leaves.iter().zip(&solution.emission).map(|(p, e)| p.area * e.element_sum()).sum();
    let rho_max = solution.rho.iter().map(|r| r.max_element()).fold(0.0, f64::max);
    let c = baked.chain_sum;
    let q = rho_max * c;
    let p_total: f64 = baked
        .radiosity
        .iter()
        .enumerate()
        .map(|(t, b)| solution.leaves[baked.solution_leaf[t]].area * b.max_element())
        .sum();
    let codes = (2f64.powi(-24) * emitted
        + (u * rho_max + 2f64.powi(-17)) * c * p_total
        + 2f64.powi(-26) * f64::from(table.longest_run()) * p_total)
        / (1.0 - q);
    CodeBound { codes, p_total, q }
}

/// The bake summary's quantization component (the f64 answer of the decoded codes against the system they were
/// quantized from) is within what the codes may change, and is not zero (the codes round).
#[test]
fn hierarchical_quantization_component_is_within_the_codes_bound() {
    let (scene, solution) = cornell_box_at_epsilon_0_1();
    let baked = bake_hierarchy(&scene, &solution, 16, false).unwrap();
    let table = HierTable::parse(&baked.table).unwrap();
    let CodeBound { codes, p_total, .. } = code_bound(&solution, &baked, &table);
    let summary = HierBakeSummary::measure(&baked, &solution).unwrap();
    let floor = summary.error_floor.expect("the summary's relight converges");
    println!(
        "quantization {:.3e} (allowed {:.3e}), device floor {floor:.3e}",
        summary.quantization,
        codes / p_total
    );
    assert!(summary.quantization > 0.0, "decoded codes differ from the f64 values they came from");
    assert!(
        summary.quantization * p_total <= codes,
        "quantization {:.3e} above the codes' bound {:.3e}",
        summary.quantization,
        codes / p_total
    );
}

/// The transfer basis of a hierarchical table: core's one-pass relight at intensities other than the defaults
/// matches the f64 answer of the table's system for those intensities within the bound of core's `transfer`
/// module, leaf by leaf and channel by channel: static base codes relative `2^-11` (emission, irradiance) and
/// the reflectance code's `2^-17`, each response within `max(2^-13 T, 2^(K - 27))`, and `2 (groups + 1)` f32
/// roundings of the magnitude.
#[test]
fn hierarchical_transfer_relight_is_within_its_quantization_bound() {
    use radiosity_core::codec::decode_emission;
    use radiosity_core::{relight_transfer, transfer_cost};
    use radiosity_host::rgb::Rgb;
    let (scene, solution) = cornell_box_at_epsilon_0_1();
    let baked = bake_hierarchy(&scene, &solution, 16, true).unwrap();
    let table = HierTable::parse(&baked.table).unwrap();
    let groups = table.group_count() as usize;
    assert!(table.has_transfer() && groups >= 1);
    // Away from the defaults: a coloured, brighter light.
    let intensity: Vec<[f32; 3]> = (0..groups).map(|g| [1.7, 0.4, 2.5].map(|v| v * (g + 1) as f32)).collect();
    let mut out = vec![[0.0f32; 3]; table.leaf_count() as usize];
    assert_eq!(relight_transfer(&table, &intensity, &mut out), Ok(transfer_cost(&table)));
    assert_eq!(transfer_cost(&table), table.leaf_count() * (groups as u32 + 1));
    let rgb: Vec<Rgb> = intensity.iter().map(|i| Rgb::new(i[0].into(), i[1].into(), i[2].into())).collect();
    let exact = baked.exact(&rgb).unwrap();
    let code = |c: u16| {
        let (m, e) = decode_emission(c);
        f64::from(m) * 2f64.powi(e)
    };
    let mut worst = 0.0f64;
    for (l, (got, want)) in out.iter().zip(&exact).enumerate() {
        let l32 = l as u32;
        let (e, g) = (table.base_emission(l32).unwrap(), table.base_irradiance(l32).unwrap());
        for c in 0..3 {
            let (es, gs) = (code(e[c]), code(g[c]));
            let mut bound = 2f64.powi(-11) * (es + gs) * (1.0 + 2f64.powi(-10)) + 2f64.powi(-17) * gs;
            let mut magnitude = es + gs;
            for (gi, i) in intensity.iter().enumerate() {
                let t = baked.responses[gi][l][c];
                let k = table.transfer().unwrap().exponent(gi as u32).unwrap()[c];
                let i = f64::from(i[c]).abs();
                bound += i * (2f64.powi(-13) * t).max(2f64.powi(i32::from(k) - 27));
                magnitude += i * t;
            }
            bound += 2.0 * (groups as f64 + 1.0) * 2f64.powi(-24) * magnitude * (1.0 + 1e-3);
            let err = (f64::from(got[c]) - want[c]).abs();
            assert!(err <= bound, "leaf {l} channel {c}: {} vs f64 {} (bound {bound:e})", got[c], want[c]);
            worst = worst.max(err / bound);
        }
    }
    println!("transfer relight of {} leaves: worst error {worst:.3} of its bound", out.len());
    assert!(worst > 0.0, "the relight must differ from f64 somewhere (codes round)");
}

/// The white furnace at rho 0.99 (a closed cube, every face emitting 1) through the hierarchical bake (16-bit
/// codes) and core's f32 shooting: every leaf within 0.5% of `E / (1 - rho) = 100` (the device tables' target for
/// a closed scene). The bake closes each leaf's row (module docs of `bake::hier`, "Closed scenes"); with the
/// open scenes' cap alone the answer lost the power the cap kept back, times `1 / (1 - rho)`.
#[test]
fn furnace_at_rho_099_through_the_hierarchical_table_gives_e_over_1_minus_rho() {
    use radiosity_host::hierarchy::Refinement;
    let dir = std::env::temp_dir().join(format!("radiosity-hier-furnace-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let furnace =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/furnace.obj")).unwrap();
    std::fs::write(dir.join("furnace.obj"), furnace.replace("mtllib furnace.mtl", "mtllib f99.mtl")).unwrap();
    std::fs::write(dir.join("f99.mtl"), "newmtl furnace\nKd 0.99 0.99 0.99\nKe 1 1 1\n").unwrap();
    let scene = Scene::load(dir.join("furnace.obj")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let solution = solve_hierarchical(
        &scene,
        &HierarchyOptions { epsilon: 0.9, refinement: Refinement::Budgets, ..HierarchyOptions::default() },
    )
    .unwrap();
    assert!(solution.stats.closed, "the furnace is closed");
    let baked = bake_hierarchy(&scene, &solution, 16, false).unwrap();
    assert!(baked.capped.self_links > 0, "some rows were below 1 and were closed");
    let table = HierTable::parse(&baked.table).unwrap();
    let emitted: f64 =
        solution.leaves.iter().zip(&solution.emission).map(|(p, e)| p.area * e.element_sum()).sum();
    let mut buffers = HierOwnedBuffers::<f32>::for_table(&table);
    let mut solver = HierSolver::new(
        &table,
        buffers.buffers(),
        Config { tolerance: (1e-9 * emitted) as f32, overshoot: 0 },
    )
    .unwrap();
    let mut steps = 0;
    while !matches!(solver.step(1_000_000), Outcome::Converged { .. }) {
        steps += 1;
        assert!(steps < 10_000, "no convergence after {steps} steps");
    }
    let mut worst = 0.0f64;
    for t in 0..table.leaf_count() {
        let b = solver.radiosity(t).unwrap();
        for c in b {
            worst = worst.max((f64::from(c) - 100.0).abs() / 100.0);
        }
    }
    println!(
        "{} leaves, {} self-links: worst leaf {:.3e} off 100",
        table.leaf_count(),
        baked.capped.self_links,
        worst
    );
    assert!(worst <= 0.005, "worst leaf {worst:.3e} off E / (1 - rho)");
}
