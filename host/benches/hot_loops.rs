//! Criterion benchmarks of core's hot loops on a baked Cornell box table (about 250 patches, 16-bit codes, with
//! the transfer section): a shooting step, a Gauss-Seidel sweep, table parsing, a decode pass over every entry,
//! and a transfer-basis relight. Run with `cargo bench -p radiosity-host`; they are not part of `make test`.

use std::hint::black_box;

use criterion::measurement::WallTime;
use criterion::{criterion_main, BenchmarkGroup, Criterion, Throughput};
use radiosity_core::{Config, Solver, Table};
use radiosity_host::bench::{cornell_table, device::Owned, roofline::stream_pass};

fn hot_loops(c: &mut Criterion) {
    let baked = cornell_table(250, 16, true).expect("bake the Cornell box");
    let table = Table::parse(&baked.table).expect("baked table parses");
    let entries = u64::from(table.entry_count());
    // Sweeps visit the rows of the patches with run-time state.
    let patches = table.state_count();

    let mut g = c.benchmark_group("core");
    // One budget of 20,000 work units of shooting from the cold start (reset is O(patches) and included).
    g.throughput(Throughput::Elements(20_000));
    from_cold(&mut g, "shot (20k units, f32)", &table, |solver| solver.step(20_000));
    // One whole Gauss-Seidel sweep (rows + entries + end scan) from the cold start.
    let sweep = u32::try_from(entries + 2 * u64::from(patches)).unwrap_or(u32::MAX);
    g.throughput(Throughput::Elements(entries));
    from_cold(&mut g, "sweep (Gauss-Seidel, f32)", &table, |solver| solver.step_gauss_seidel(sweep));
    g.throughput(Throughput::Bytes(baked.table.len() as u64));
    g.bench_function("parse", |b| b.iter(|| black_box(Table::parse(black_box(&baked.table)).is_ok())));
    g.throughput(Throughput::Elements(entries));
    g.bench_function("decode (stream pass, f32)", |b| {
        let mut acc = vec![[0.0f32; 3]; patches as usize];
        b.iter(|| {
            stream_pass(black_box(&table), black_box([1.0f32, 0.5, 0.25]), &mut acc);
            black_box(&acc);
        });
    });
    // One relight from the transfer basis at a new intensity of every group (patches x (groups + 1) units).
    g.throughput(Throughput::Elements(u64::from(radiosity_core::transfer_cost(&table))));
    g.bench_function("transfer relight (f32)", |b| {
        let intensity = vec![[1.0f32, 0.5, 0.25]; table.group_count() as usize];
        let mut out = vec![[0.0f32; 3]; patches as usize];
        b.iter(|| black_box(radiosity_core::relight_transfer(&table, black_box(&intensity), &mut out)));
    });
    g.finish();
}

/// Benchmarks `step` on an f32 solver of `table` (tolerance 0, no overshooting), reset to the cold start before
/// every iteration.
fn from_cold<R>(
    g: &mut BenchmarkGroup<'_, WallTime>,
    name: &str,
    table: &Table<'_>,
    step: impl Fn(&mut Solver<'_, f32>) -> R,
) {
    let config = Config { tolerance: 0.0f32, overshoot: 0 };
    g.bench_function(name, |b| {
        let mut owned = Owned::<f32>::new(table);
        let (buffers, _) = owned.split();
        let mut solver = Solver::new(table, buffers, config).expect("solver");
        b.iter(|| {
            solver.reset();
            black_box(step(&mut solver))
        });
    });
}

// The macro defines an undocumented `benches` function.
#[allow(missing_docs)]
mod group {
    criterion::criterion_group!(benches, super::hot_loops);
}
criterion_main!(group::benches);
