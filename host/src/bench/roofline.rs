//! The roofline: how fast shooting applies form-factor entries compared with a straight streaming pass over the
//! same table bytes.
//!
//! - **Streaming pass**: every row in order, every entry decoded with the table's own accessor
//!   ([`Table::entry`], the decode the solver uses) and multiplied into an RGB accumulator of its receiver
//!   (`acc_j += p * F_ij`, [`Scalar::mul_frac`]). No selection, no reflectance, one output buffer: the least work
//!   any method that reads every entry must do.
//! - **Gauss-Seidel**: core's sweep, whole sweeps; each entry as in shooting (decode, reflectance lookup, three
//!   buffers) but no selection. Entries per sweep are the table's entry count.
//! - **Shooting**: core's [`Solver::step`] to convergence at a tolerance; entries applied as counted by the
//!   solver ([`Solver::entries`]).
//!
//! The differences locate the time: stream to Gauss-Seidel is the per-entry reflectance decode and the two extra
//! buffers; Gauss-Seidel to shooting is the selection and per-shot work (its units per entry are reported).

use std::hint::black_box;
use std::time::Instant;

use radiosity_core::{Config, Outcome, Scalar, Solver, Table};

use super::device::{median, Owned};
use super::BenchError;
use crate::bake::Capacities;

/// Throughputs of one table.
#[derive(Clone, Debug, PartialEq)]
pub struct Roofline {
    /// Entries in the table.
    pub entries: u64,
    /// Streaming pass: entries per second (median).
    pub stream_entries_per_s: f64,
    /// Gauss-Seidel: entries per second (median).
    pub gauss_seidel_entries_per_s: f64,
    /// Shooting: entries per second (median).
    pub shooting_entries_per_s: f64,
    /// Shooting: entries applied in the timed solve.
    pub shooting_entries: u64,
    /// Shooting: work units of the timed solve.
    pub shooting_units: u64,
    /// Shooting: rows shot.
    pub shots: u64,
}

impl Roofline {
    /// Shooting's entries per second as a fraction of the streaming pass.
    #[must_use]
    pub fn shooting_fraction(&self) -> f64 {
        self.shooting_entries_per_s / self.stream_entries_per_s
    }
}

/// One streaming pass: decode every entry and accumulate `p * F` into its receiver (`acc` indexed by slot,
/// the table's state count).
pub fn stream_pass<S: Scalar>(table: &Table<'_>, power: [S; 3], acc: &mut [[S; 3]]) {
    for i in 0..table.state_count() {
        for k in table.row(i).unwrap_or(0..0) {
            if let Some((j, f)) = table.entry(i, k) {
                if let Some(a) = acc.get_mut(j as usize) {
                    for c in 0..3 {
                        a[c] = a[c].add(power[c].mul_frac(f));
                    }
                }
            }
        }
    }
}

/// Measures the three throughputs on `table` in arithmetic `S` (see the module docs), `reps` repetitions each;
/// shooting runs to convergence at `tolerance` (power units).
///
/// # Errors
/// If the solver cannot be created or a solve makes no progress.
pub fn measure<S: Scalar>(
    table: &Table<'_>,
    caps: &Capacities,
    tolerance: f64,
    reps: usize,
) -> Result<Roofline, BenchError> {
    let n = table.state_count() as usize;
    let entries = u64::from(table.entry_count());
    let reps = reps.max(1);
    let config = Config { tolerance: S::from_f32(tolerance as f32), overshoot: 0 };
    let err = |e: radiosity_core::SolverError| BenchError::Solver(format!("roofline: {e}"));

    // Passes per timing so each timing covers at least ~2e7 entries (timer resolution and noise).
    let passes = (2e7 / entries.max(1) as f64).ceil().clamp(1.0, 1000.0) as usize;
    let mut acc = vec![[S::from_f32(0.0); 3]; n];
    let p = [S::from_f32(1.0), S::from_f32(0.5), S::from_f32(0.25)];
    let mut t_stream = Vec::new();
    for _ in 0..reps {
        let t0 = Instant::now();
        for _ in 0..passes {
            stream_pass(black_box(table), black_box(p), &mut acc);
        }
        t_stream.push(t0.elapsed().as_secs_f64() / passes as f64);
        black_box(&acc);
    }
    let stream = entries as f64 / median(&mut t_stream);

    // Gauss-Seidel: whole sweeps (budget = rows + entries + scan per sweep).
    let sweep_units = u64::from(table.entry_count()) + 2 * n as u64;
    let mut t_gs = Vec::new();
    for _ in 0..reps {
        let mut owned = Owned::<S>::new(caps);
        let (buffers, _) = owned.split();
        let mut solver = Solver::new(table, buffers, config).map_err(err)?;
        let t0 = Instant::now();
        let mut swept = 0usize;
        for _ in 0..passes.max(2) {
            let budget = u32::try_from(sweep_units).unwrap_or(u32::MAX);
            match solver.step_gauss_seidel(table, budget) {
                Outcome::BudgetSpent { .. } => swept += 1,
                Outcome::Converged { .. } => {
                    swept += 1;
                    break;
                }
                Outcome::NoProgress { reason, .. } => {
                    return Err(BenchError::Solver(format!("roofline Gauss-Seidel: {reason:?}")))
                }
            }
        }
        t_gs.push(t0.elapsed().as_secs_f64() / swept as f64);
    }
    let gauss_seidel = entries as f64 / median(&mut t_gs);

    // Shooting: time the solve; the solver counts the entries it applied.
    let (mut shooting_entries, mut shooting_units, mut shots) = (0u64, 0u64, 0u64);
    let mut t_shoot = Vec::new();
    for rep in 0..reps {
        let mut owned = Owned::<S>::new(caps);
        let (buffers, _) = owned.split();
        let mut solver = Solver::new(table, buffers, config).map_err(err)?;
        let t0 = Instant::now();
        let mut units = 0u64;
        loop {
            let o = solver.step(table, u32::MAX);
            units += u64::from(o.used());
            match o {
                Outcome::BudgetSpent { .. } => {}
                Outcome::Converged { .. } => break,
                Outcome::NoProgress { reason, .. } => {
                    return Err(BenchError::Solver(format!("roofline shooting: {reason:?}")))
                }
            }
        }
        t_shoot.push(t0.elapsed().as_secs_f64());
        let run = (solver.entries(), units, u64::from(solver.shots()));
        if rep > 0 && run != (shooting_entries, shooting_units, shots) {
            return Err(BenchError::Solver(format!(
                "roofline: shooting is not deterministic: {run:?} vs {:?}",
                (shooting_entries, shooting_units, shots)
            )));
        }
        (shooting_entries, shooting_units, shots) = run;
    }
    let shooting = shooting_entries as f64 / median(&mut t_shoot);
    Ok(Roofline {
        entries,
        stream_entries_per_s: stream,
        gauss_seidel_entries_per_s: gauss_seidel,
        shooting_entries_per_s: shooting,
        shooting_entries,
        shooting_units,
        shots,
    })
}
