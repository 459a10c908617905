use radiosity_core::{Config, HierOwnedBuffers, HierSolver, HierTable, Outcome};
use radiosity_host::bake::bake_hierarchy;
use radiosity_host::hierarchy::{solve_hierarchical, HierarchyOptions};
use radiosity_host::scene::Scene;

fn main() {
    let scene = Scene::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/cornell-box.obj")).unwrap();
    let args: Vec<String> = std::env::args().collect();
    let eps: f64 = args[1].parse().unwrap();
    let passes: usize = args[2].parse().unwrap();
    let t = std::time::Instant::now();
    let sol =
        solve_hierarchical(&scene, &HierarchyOptions { epsilon: eps, passes, ..HierarchyOptions::default() })
            .unwrap();
    let el = t.elapsed().as_secs_f64();
    let baked = bake_hierarchy(&scene, &sol, 16).unwrap();
    let table = HierTable::parse(&baked.table).unwrap();
    let (nodes, leaves, links) = baked.counts;
    let mut buffers = HierOwnedBuffers::<f32>::for_table(&table);
    let mut solver =
        HierSolver::new(&table, buffers.buffers(), Config { tolerance: 0.0, overshoot: 0 }).unwrap();
    let area: Vec<f64> = baked.solution_leaf.iter().map(|&l| sol.leaves[l].area).collect();
    let total: f64 = baked.radiosity.iter().zip(&area).map(|(b, a)| a * b.max_element()).sum();
    let mut units = 0u64;
    let mut reached = None;
    for _ in 0..2000 {
        let o = solver.step(10_000);
        units += 10_000;
        let err: f64 = baked
            .radiosity
            .iter()
            .zip(&area)
            .enumerate()
            .map(|(t, (b, a))| {
                let g = solver.radiosity(t as u32).unwrap();
                a * (0..3).map(|c| (g[c] as f64 - b[c]).abs()).fold(0.0, f64::max)
            })
            .sum::<f64>()
            / total;
        if err < 0.01 && reached.is_none() {
            reached = Some(units);
        }
        if matches!(o, Outcome::Converged { .. }) || reached.is_some() {
            break;
        }
    }
    println!("eps {eps} passes {passes}: {leaves} leaves {nodes} nodes {links} links, {} bytes ({:.0}/leaf), solve {el:.2}s, cap {:?}, 1% at {:?} units, links walked {}, shots {}",
        baked.table.len(), baked.table.len() as f64 / leaves as f64, baked.capped, reached, solver.links(), solver.shots());
}
