//! One benchmark scene: meshed to a patch count, its exact f64 answer, a bake per codec, and every curve run
//! on it (the curves themselves are measured in `curves.rs`).

use std::path::Path;
use std::time::Instant;

use firmware_sim::sim::Arith;
use radiosity_core::Table;

use super::curves::{host_curves, SceneRun};
use super::device::{DeviceCase, Start, StopRule};
use super::{default_scenes_dir, log, roofline, BenchError, BenchOptions, Curve, CurveMethod, DeviceRun};
use super::{InstructionsPerUnit, SceneResult};
use crate::bake::{self, bake, codec_for_bits, BakeInput, BakeOptions};
use crate::formfactor::FormFactorOptions;
use crate::mesh::{mesh, MeshOptions};
use crate::pipeline::{prepare, PrepareOptions, Prepared};
use crate::reference::{exact_transfer, GaussSeidelOptions, Method};
use crate::rgb::{max_channel, Rgb};
use crate::scene::Scene;

/// A benchmark scene: a file of the scenes folder meshed to about `target` patches, with the reflectance
/// optionally overridden.
pub(super) struct SceneSpec {
    /// Name in the report and the CSV files.
    pub(super) name: String,
    /// File in the scenes folder.
    file: &'static str,
    /// Patch count aimed at.
    target: usize,
    /// Reflectance of every material and patch, if overridden.
    rho: Option<f64>,
}

impl SceneSpec {
    /// The Cornell box at about `target` patches (`cornell-TARGET`).
    pub(super) fn cornell(target: usize) -> Self {
        SceneSpec { name: format!("cornell-{target}"), file: "cornell-box.obj", target, rho: None }
    }

    /// The white furnace at about `target` patches, reflectance `rho` everywhere (`furnace-rhoPERCENT`).
    pub(super) fn furnace(target: usize, rho: f64) -> Self {
        let name = format!("furnace-rho{}", (rho * 100.0).round());
        SceneSpec { name, file: "furnace.obj", target, rho: Some(rho) }
    }
}

/// Form factors of the benchmark scenes: fewer samples and rays than the bake's default (16/16) so the
/// 4,000-patch mesh fits the run; every error is against the exact solve of the same matrix, so the
/// estimator's own noise does not enter the curves. The throughput section uses the defaults.
pub(super) fn form_factor_options() -> FormFactorOptions {
    FormFactorOptions {
        samples_per_patch: 4,
        rays_per_pair: 4,
        progress: false,
        ..FormFactorOptions::default()
    }
}

/// The bake of the benchmark tables with `bits`-bit codes (and the transfer section if `transfer`).
///
/// Row-sum slack of the bake's f64 solves: the shooting form `A_j F_ji / A_i` of a matrix estimated with few
/// samples exceeds 1 by up to the estimator's reciprocity noise (~1e-3 here), more than the default 1e-4.
fn bake_options(bits: u32, transfer: bool) -> Result<BakeOptions, BenchError> {
    Ok(BakeOptions {
        codec: codec_for_bits(bits)?,
        row_sum_tolerance: 1e-2,
        transfer,
        ..BakeOptions::default()
    })
}

/// Bakes the prepared scene.
pub(super) fn bake_prepared(p: &Prepared, options: &BakeOptions) -> Result<bake::Baked, BenchError> {
    Ok(bake(&BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors), options)?)
}

/// The uniform-subdivision edge whose mesh of `scene` has the patch count closest to `target` (bisection on
/// the edge's logarithm; patch counts fall as the edge grows).
///
/// # Errors
/// If meshing fails.
pub fn edge_for_patches(scene: &Scene, target: usize) -> Result<(f64, usize), BenchError> {
    let base = MeshOptions::for_scene(scene);
    let count = |edge: f64| -> Result<usize, BenchError> {
        let o = MeshOptions { subdivide: true, max_patch_edge: edge, patch_budget: usize::MAX / 4, ..base };
        mesh(scene, &o)
            .map(|m| m.patches.len())
            .map_err(|e| BenchError::Options(format!("meshing {}: {e}", scene.path.display())))
    };
    let (mut lo, mut hi) = ((base.max_patch_edge / 64.0).ln(), (base.max_patch_edge * 16.0).ln());
    let mut best = (base.max_patch_edge, count(base.max_patch_edge)?);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        let c = count(mid.exp())?;
        if c.abs_diff(target) < best.1.abs_diff(target) {
            best = (mid.exp(), c);
        }
        if c > target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(best)
}

fn prepare_at(
    path: &Path,
    target: usize,
    ff: &FormFactorOptions,
    rho: Option<f64>,
) -> Result<Prepared, BenchError> {
    let scene = Scene::load(path)?;
    let (edge, count) = edge_for_patches(&scene, target)?;
    // A patch budget equal to the uniform mesh's count: adaptive refinement has nothing left to spend, so the
    // mesh is the uniform one of about `target` patches (the sizes the report compares).
    let options = PrepareOptions {
        no_subdivide: false,
        max_patch_edge: Some(edge),
        max_patches: Some(count),
        repair: true,
        form_factors: ff.clone(),
        verbose: false,
    };
    let mut p = prepare(path, &options)?;
    if let Some(r) = rho {
        for m in &mut p.scene.materials {
            m.reflectance = Rgb::splat(r);
        }
        for v in &mut p.lighting.rho {
            *v = Rgb::splat(r);
        }
    }
    Ok(p)
}

/// The Cornell box meshed to about `target` patches (form factors at 4 samples and 4 rays), baked with `bits`-bit
/// codes, with the transfer section if `transfer`: the table the criterion benchmarks run on.
///
/// # Errors
/// If preparing or baking fails.
pub fn cornell_table(target: usize, bits: u32, transfer: bool) -> Result<bake::Baked, BenchError> {
    let path = default_scenes_dir().join("cornell-box.obj");
    let p = prepare_at(&path, target, &form_factor_options(), None)?;
    bake_prepared(&p, &bake_options(bits, transfer)?)
}

/// Intensity per dynamic group after the light change: `(1, 0.2, 0.2)` times the default.
fn changed_intensity(p: &Prepared) -> Vec<Rgb> {
    p.lighting.default_intensity.iter().map(|&d| d * Rgb::new(1.0, 0.2, 0.2)).collect()
}

fn stop_rule(entries: usize, patches: usize, rho_max: f64, quick: bool) -> StopRule {
    // Enough passes over the table for Jacobi (the slowest, contraction rho_max per sweep) to reach the stop
    // error, times 4 as a margin (shooting's work units per entry were up to about 3 with the earlier
    // tournament tree; about 1.1 with block selection).
    let error: f64 = 3e-4;
    let passes = (error.ln() / rho_max.max(0.05).ln()).ceil() + 10.0;
    StopRule {
        first: (entries as u64 / 64).max(64),
        ratio: if quick { 1.6 } else { 1.3 },
        error,
        max_work: (passes * 4.0 * entries as f64) as u64,
        plateau: if quick { 3 } else { 5 },
        // A floor is only declared after the passes Jacobi needs to reach 10% (at least four passes; a pass is
        // entries + 2 units per patch), times 4 as a margin: at rho = 0.99 the error falls ~1% per
        // pass, which a fixed window would mistake for a plateau.
        plateau_after: ((0.1f64.ln() / rho_max.max(0.05).ln()).ceil().max(4.0) * 4.0) as u64
            * (entries + 2 * patches) as u64,
    }
}

/// Runs `spec`: every curve on both codecs, the roofline and the host's references; with `growth_only`, only
/// the 16-bit bake and f32 shooting to 1% (the growth series' sizes).
pub(super) fn run_scene(
    options: &BenchOptions,
    spec: &SceneSpec,
    ff: &FormFactorOptions,
    instr: InstructionsPerUnit,
    growth_only: bool,
) -> Result<(SceneResult, Vec<Curve>), BenchError> {
    let path = options.scenes.join(spec.file);
    let t0 = Instant::now();
    let p = prepare_at(&path, spec.target, ff, spec.rho)?;
    let n = p.patches.len();
    log(
        options,
        &format!(
            "{}: {} patches, {} nonzeros, form factors {:.1} s",
            spec.name,
            n,
            p.form_factors.nonzeros(),
            t0.elapsed().as_secs_f64()
        ),
    );
    // The exact answer's transfer vectors on the scene's own matrix (f64 Gauss-Seidel to residual `1e-12`: the
    // forward error is at most `(1 + q) / (1 - q) * 1e-12`, `2e-10` at `q = 0.99`).
    let exact = Method::GaussSeidel(GaussSeidelOptions::default());
    let tv = exact_transfer(&p.lighting, &p.form_factors, &exact)?;
    let exact_default = tv.relight(&p.lighting.default_intensity)?;
    let changed = changed_intensity(&p);
    let exact_changed = tv.relight(&changed)?;
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let rho_max = p.lighting.rho.iter().fold(0.0, |m: f64, &r| m.max(max_channel(r)));

    let mut run = SceneRun { options, name: &spec.name, instr, curves: Vec::new() };
    let mut result = SceneResult {
        name: spec.name.clone(),
        patches: n,
        nonzeros: p.form_factors.nonzeros(),
        entries: Vec::new(),
        table_bytes: Vec::new(),
        form_factor_seconds: p.stats.elapsed.as_secs_f64(),
        bake_seconds: 0.0,
        roofline: Vec::new(),
        lu_reps: 0,
    };
    let bits_list: &[u32] = if growth_only { &[16] } else { &[16, 8] };
    for &bits in bits_list {
        let tb = Instant::now();
        let baked = bake_prepared(&p, &bake_options(bits, false)?)?;
        if bits == 16 {
            result.bake_seconds = tb.elapsed().as_secs_f64();
        }
        let table = Table::parse(&baked.table).map_err(|e| BenchError::Solver(format!("table: {e:?}")))?;
        let bytes = baked.table.len();
        result.entries.push((bits, table.entry_count() as usize));
        result.table_bytes.push((bits, bytes));
        let dec = bake::decode_table(&table);
        let max_power = (0..3)
            .map(|c| dec.emission.iter().zip(&dec.area).map(|(e, a)| e[c] * a).sum::<f64>())
            .fold(0.0, f64::max);
        // Converged = every unshot magnitude below 1e-6 of the emitted power (as `radiosity check`).
        let case = DeviceCase { table: &table, area: &area, tolerance: 1e-6 * max_power };
        let stop = stop_rule(table.entry_count() as usize, n, rho_max, options.quick);
        let (cold, ex) = (Start::Cold, &exact_default);
        if growth_only {
            let s = StopRule { error: 0.01, ..stop };
            run.device(&case, DeviceRun::shooting(Arith::F32, bits, false), bytes, &cold, ex, &s)?;
            continue;
        }
        for overshoot in [false, true] {
            for arith in Arith::ALL {
                run.device(&case, DeviceRun::shooting(arith, bits, overshoot), bytes, &cold, ex, &stop)?;
            }
        }
        for method in [CurveMethod::GaussSeidel, CurveMethod::Jacobi] {
            for arith in Arith::ALL {
                run.device(&case, DeviceRun::new(method, arith, bits), bytes, &cold, ex, &stop)?;
            }
        }
        if bits == 16 {
            let to: Vec<[f32; 3]> = changed.iter().map(|v| v.as_vec3().to_array()).collect();
            let s = StopRule { first: 1, ..stop };
            let relight = |method| DeviceRun::new(method, Arith::F32, bits);
            let ec = &exact_changed;
            run.device(&case, relight(CurveMethod::WarmRelight), bytes, &Start::Warm(to.clone()), ec, &s)?;
            run.device(&case, relight(CurveMethod::ColdRelight), bytes, &Start::ColdAt(to), ec, &s)?;
        }
        let transfer = bake_prepared(&p, &bake_options(bits, true)?)?;
        run.transfer(&transfer, &p.lighting.default_intensity, bits, ex, &area)?;
        let tr = Instant::now();
        // Three rounds per repetition: each round is short (~1 s), and the ratios need several on a shared machine.
        let rounds = 3 * options.reps;
        let roof = roofline::measure::<f32>(&table, 1e-3 * max_power, rounds)?;
        log(
            options,
            &format!(
                "{}: roofline {bits}-bit: stream {:.1} M/s, GS {:.1} M/s, shooting {:.1} M/s ({:.0}%) ({:.1} s)",
                spec.name,
                roof.stream_entries_per_s / 1e6,
                roof.gauss_seidel_entries_per_s / 1e6,
                roof.shooting_entries_per_s / 1e6,
                100.0 * roof.shooting_fraction(),
                tr.elapsed().as_secs_f64()
            ),
        );
        result.roofline.push((bits, roof));
    }
    if !growth_only {
        let (host, lu_reps) = host_curves(options, &spec.name, &p, &exact_default)?;
        result.lu_reps = lu_reps;
        for c in &host {
            log(options, &format!("{}: {} -> final error {:.2e}", spec.name, c.label(), c.floor()));
        }
        run.curves.extend(host);
    }
    Ok((result, run.curves))
}
