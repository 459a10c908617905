//! How each kind of curve is measured on one scene: device curves (core's solver through [`super::device`]),
//! the transfer basis (one relight from the table's stored basis), and the host's f64 references.

use std::time::Instant;

use firmware_sim::sim::Arith;
use radiosity_core::{Fixed, Scalar, Table};

use super::device::{self, run_curve, DeviceCase, Start, Step, StopRule};
use super::{
    log, BenchError, BenchOptions, Curve, CurveMethod, CurvePoint, DeviceRun, InstructionsPerUnit, OVERSHOOT,
};
use crate::bake::Baked;
use crate::metrics;
use crate::pipeline::Prepared;
use crate::reference::{gauss_seidel, DenseLu, GaussSeidelOptions, RadiositySystem};
use crate::rgb::Rgb;

/// The core step a device curve runs: shooting (the relights too) with or without overshooting, or a sweep.
fn step(run: DeviceRun) -> Step {
    match run.method {
        CurveMethod::GaussSeidel => Step::GaussSeidel,
        CurveMethod::Jacobi => Step::Jacobi,
        _ => Step::Shooting(if run.overshoot { OVERSHOOT } else { 0 }),
    }
}

/// The curves measured so far on one scene.
pub(super) struct SceneRun<'a> {
    /// The bench's settings.
    pub(super) options: &'a BenchOptions,
    /// Scene name.
    pub(super) name: &'a str,
    /// Model instructions per work unit.
    pub(super) instr: InstructionsPerUnit,
    /// The curves, in the order they ran.
    pub(super) curves: Vec<Curve>,
}

impl SceneRun<'_> {
    /// Runs the device curve `run` on `case` (a table of `table_bytes` bytes) from `start` against `exact`.
    pub(super) fn device(
        &mut self,
        case: &DeviceCase<'_>,
        run: DeviceRun,
        table_bytes: usize,
        start: &Start,
        exact: &[Rgb],
        stop: &StopRule,
    ) -> Result<(), BenchError> {
        let per_unit = self.instr.of(run.arith);
        let t0 = Instant::now();
        let reps = self.options.reps;
        let points = match run.arith {
            Arith::F32 => run_curve::<f32>(case, step(run), start, exact, stop, reps)?,
            Arith::Fixed => run_curve::<Fixed>(case, step(run), start, exact, stop, reps)?,
        };
        let curve = Curve {
            scene: self.name.to_string(),
            method: run.method,
            arith: Some(run.arith),
            bits: Some(run.bits),
            overshoot: run.overshoot,
            table_bytes,
            points: points
                .iter()
                .map(|p| CurvePoint {
                    work: Some(p.work),
                    instructions: Some(p.work as f64 * per_unit),
                    seconds: p.seconds,
                    rel_l2: p.rel_l2,
                    max_rel: p.max_rel,
                })
                .collect(),
        };
        log(
            self.options,
            &format!(
                "{}: {} -> {} points, final error {:.2e} ({:.1} s)",
                self.name,
                curve.label(),
                curve.points.len(),
                curve.floor(),
                t0.elapsed().as_secs_f64()
            ),
        );
        self.curves.push(curve);
        Ok(())
    }

    /// The precomputed transfer basis: `baked` is the scene's `bits`-bit bake with the quantized response
    /// vectors `T_g` stored in the table, relit once by core's `relight_transfer` (f32 and fixed point) at
    /// `intensity`. One point per curve: its work is `patches x (groups + 1)` units, its error the quantization
    /// of `B_static` and `T_g` (no iteration), its bytes the table with the transfer section.
    pub(super) fn transfer(
        &mut self,
        baked: &Baked,
        intensity: &[Rgb],
        bits: u32,
        exact: &[Rgb],
        area: &[f64],
    ) -> Result<(), BenchError> {
        let table = Table::parse(&baked.table).map_err(|e| BenchError::Solver(format!("table: {e:?}")))?;
        for arith in Arith::ALL {
            let run = DeviceRun::new(CurveMethod::TransferBasis, arith, bits);
            let (work, seconds, b) = match arith {
                Arith::F32 => self.relight_transfer::<f32>(&table, intensity)?,
                Arith::Fixed => self.relight_transfer::<Fixed>(&table, intensity)?,
            };
            let e = metrics::compare(&b, exact, area)?;
            let curve = Curve {
                scene: self.name.to_string(),
                method: run.method,
                arith: Some(arith),
                bits: Some(bits),
                overshoot: false,
                table_bytes: baked.table.len(),
                points: vec![CurvePoint {
                    work: Some(u64::from(work)),
                    instructions: Some(f64::from(work) * self.instr.transfer_of(arith)),
                    seconds,
                    rel_l2: e.rel_l2,
                    max_rel: e.max_rel,
                }],
            };
            log(
                self.options,
                &format!(
                    "{}: {} -> {} units, error {:.2e}, table {} bytes",
                    self.name,
                    curve.label(),
                    work,
                    e.rel_l2,
                    baked.table.len()
                ),
            );
            self.curves.push(curve);
        }
        Ok(())
    }

    /// Core's transfer relight in `S`, repeated: its work units, its median time (the upper one of an even
    /// count) and the radiosity in f64.
    fn relight_transfer<S: Scalar>(
        &self,
        table: &Table<'_>,
        intensity: &[Rgb],
    ) -> Result<(u32, f64, Vec<Rgb>), BenchError> {
        let intensity: Vec<[S; 3]> =
            intensity.iter().map(|v| v.as_vec3().to_array().map(S::from_f32)).collect();
        let mut out = vec![[S::ZERO; 3]; table.patch_count() as usize];
        let mut times = Vec::new();
        let mut work = 0;
        for _ in 0..self.options.reps.max(1) {
            let t0 = Instant::now();
            work = radiosity_core::transfer::relight_transfer(table, &intensity, &mut out)
                .map_err(|e| BenchError::Solver(format!("transfer relight: {e:?}")))?;
            times.push(t0.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let b: Vec<Rgb> = out.iter().map(|v| Rgb::from_array(v.map(|x| f64::from(x.to_f32())))).collect();
        Ok((work, times[times.len() / 2], b))
    }
}

/// Size of the f64 CSR matrix the host methods read (values, column indices, row starts).
fn csr_bytes(p: &Prepared) -> usize {
    let ff = &p.form_factors;
    ff.values().len() * 8 + ff.columns().len() * 4 + ff.row_starts().len() * 8
}

/// A curve of the host's f64 method `method` on scene `name`.
fn host_curve(name: &str, method: CurveMethod, table_bytes: usize, points: Vec<CurvePoint>) -> Curve {
    Curve { scene: name.into(), method, arith: None, bits: None, overshoot: false, table_bytes, points }
}

/// The host's f64 curves: dense LU (one point) and Gauss-Seidel at decreasing residual tolerances; also the
/// repetitions of the LU timing.
pub(super) fn host_curves(
    options: &BenchOptions,
    name: &str,
    p: &Prepared,
    exact: &[Rgb],
) -> Result<(Vec<Curve>, usize), BenchError> {
    let l = &p.lighting;
    let e = l.default_emission();
    let area: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let system = RadiositySystem::new(&l.rho, &p.form_factors)?;
    let n = p.patches.len();
    let point = |b: &[Rgb], times: &mut [f64]| -> Result<CurvePoint, BenchError> {
        let err = metrics::compare(b, exact, &area)?;
        Ok(CurvePoint {
            work: None,
            instructions: None,
            seconds: device::median(times),
            rel_l2: err.rel_l2,
            max_rel: err.max_rel,
        })
    };
    let mut curves = Vec::new();
    // Dense LU: factor + solve; a factorization of thousands of patches takes seconds, so large scenes repeat less.
    let lu_reps = if n > 2000 { 1 } else { options.reps };
    let mut times = Vec::new();
    let mut b = Vec::new();
    for _ in 0..lu_reps {
        let t0 = Instant::now();
        let lu = DenseLu::factor(system)?;
        b = lu.solve(&e)?.b;
        times.push(t0.elapsed().as_secs_f64());
    }
    curves.push(host_curve(name, CurveMethod::DenseLu, n * n * 8, vec![point(&b, &mut times)?]));
    // f64 Gauss-Seidel stopped at residual tolerances 10^-1 .. 10^-8 (half decades).
    let mut points = Vec::new();
    let mut k = 2;
    while k <= 16 {
        let tolerance = 10f64.powf(-(k as f64) / 2.0);
        let mut times = Vec::new();
        let mut sol = None;
        for _ in 0..options.reps {
            let t0 = Instant::now();
            let s = gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance, max_sweeps: None })?;
            times.push(t0.elapsed().as_secs_f64());
            sol = Some(s);
        }
        if let Some(s) = sol {
            let p = point(&s.b, &mut times)?;
            points.push(p);
            if p.rel_l2 < 1e-6 {
                break;
            }
        }
        k += if options.quick { 2 } else { 1 };
    }
    curves.push(host_curve(name, CurveMethod::HostGaussSeidel, csr_bytes(p), points));
    Ok((curves, lu_reps))
}
