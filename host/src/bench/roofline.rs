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

/// Throughputs of one table.
#[derive(Clone, Debug, PartialEq)]
pub struct Roofline {
    /// Entries in the table.
    pub entries: u64,
    /// Streaming pass: entries per second (median over rounds).
    pub stream_entries_per_s: f64,
    /// Gauss-Seidel: entries per second (median over rounds).
    pub gauss_seidel_entries_per_s: f64,
    /// Shooting: entries per second (median over rounds).
    pub shooting_entries_per_s: f64,
    /// Shooting's rate over the stream's, median of the ratios measured in the same round.
    pub shooting_over_stream: f64,
    /// Gauss-Seidel's rate over the stream's, median of the ratios measured in the same round.
    pub gauss_seidel_over_stream: f64,
    /// Rounds measured (each times all three loops, one after the other).
    pub rounds: usize,
    /// Shooting: entries applied in one timed solve.
    pub shooting_entries: u64,
    /// Shooting: work units of one timed solve.
    pub shooting_units: u64,
    /// Shooting: rows shot in one solve.
    pub shots: u64,
}

impl Roofline {
    /// Shooting's entries per second as a fraction of the streaming pass (median of same-round ratios).
    #[must_use]
    pub fn shooting_fraction(&self) -> f64 {
        self.shooting_over_stream
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

/// Measures the three throughputs on `table` in arithmetic `S` (see the module docs) in `rounds` rounds;
/// shooting runs to convergence at `tolerance` (power units).
///
/// Each round times the stream, Gauss-Seidel and shooting one after the other, each over at least ~2e7 entries
/// (repeated passes, sweeps or solves), so the three rates of a round see the same machine: on a shared machine
/// the speed drifts between rounds, and the ratios are taken within a round before the median over rounds.
///
/// # Errors
/// If the solver cannot be created, a solve makes no progress, or shooting is not deterministic.
pub fn measure<S: Scalar>(table: &Table<'_>, tolerance: f64, rounds: usize) -> Result<Roofline, BenchError> {
    let n = table.state_count() as usize;
    let entries = u64::from(table.entry_count());
    let rounds = rounds.max(1);
    let config = Config { tolerance: S::from_f32(tolerance as f32), overshoot: 0 };
    let err = |e: radiosity_core::SolverError| BenchError::Solver(format!("roofline: {e}"));
    let repeats = |per: u64| (2e7 / per.max(1) as f64).ceil().clamp(1.0, 1000.0) as usize;

    let mut acc = vec![[S::from_f32(0.0); 3]; n];
    let p = [S::from_f32(1.0), S::from_f32(0.5), S::from_f32(0.25)];
    let mut owned = Owned::<S>::new(table);
    let (buffers, _) = owned.split();
    let mut solver = Solver::new(table, buffers, config).map_err(err)?;
    let sweep_units = u32::try_from(entries + 2 * n as u64).unwrap_or(u32::MAX);

    // One untimed solve: the entries per solve (for the repeat count) and the determinism reference.
    let solve = |solver: &mut Solver<'_, S>| -> Result<(u64, u64, u64), BenchError> {
        solver.reset();
        let mut units = 0u64;
        loop {
            let o = solver.step(u32::MAX);
            units += u64::from(o.used());
            match o {
                Outcome::BudgetSpent { .. } => {}
                Outcome::Converged { .. } => break,
                Outcome::NoProgress { reason, .. } => {
                    return Err(BenchError::Solver(format!("roofline shooting: {reason:?}")))
                }
            }
        }
        Ok((solver.entries(), units, u64::from(solver.shots())))
    };
    let reference = solve(&mut solver)?;
    let (shooting_entries, shooting_units, shots) = reference;

    let (mut stream, mut gs, mut shoot) = (Vec::new(), Vec::new(), Vec::new());
    let (mut shoot_ratio, mut gs_ratio) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        let passes = repeats(entries);
        let t0 = Instant::now();
        for _ in 0..passes {
            stream_pass(black_box(table), black_box(p), &mut acc);
        }
        let r_stream = (entries * passes as u64) as f64 / t0.elapsed().as_secs_f64();
        black_box(&acc);

        // Gauss-Seidel: whole sweeps from a cold start (budget = rows + entries + scan per sweep).
        solver.reset();
        let t0 = Instant::now();
        let mut swept = 0u64;
        for _ in 0..passes.max(2) {
            match solver.step_gauss_seidel(sweep_units) {
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
        let r_gs = (entries * swept) as f64 / t0.elapsed().as_secs_f64();

        // Shooting: whole solves; the solver counts the entries it applied.
        let solves = repeats(shooting_entries);
        let mut seconds = 0.0;
        for _ in 0..solves {
            let t0 = Instant::now();
            let run = solve(&mut solver)?;
            seconds += t0.elapsed().as_secs_f64();
            if run != reference {
                return Err(BenchError::Solver(format!(
                    "roofline: shooting is not deterministic: {run:?} vs {reference:?}"
                )));
            }
        }
        let r_shoot = (shooting_entries * solves as u64) as f64 / seconds;
        stream.push(r_stream);
        gs.push(r_gs);
        shoot.push(r_shoot);
        shoot_ratio.push(r_shoot / r_stream);
        gs_ratio.push(r_gs / r_stream);
    }
    Ok(Roofline {
        entries,
        stream_entries_per_s: median(&mut stream),
        gauss_seidel_entries_per_s: median(&mut gs),
        shooting_entries_per_s: median(&mut shoot),
        shooting_over_stream: median(&mut shoot_ratio),
        gauss_seidel_over_stream: median(&mut gs_ratio),
        rounds,
        shooting_entries,
        shooting_units,
        shots,
    })
}
