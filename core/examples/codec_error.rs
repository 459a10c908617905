//! Measures the form-factor codecs on a closed cube: per-row error, table size, and the error each codec
//! causes in a solve (against a solve with the unquantized f32 form factors).
//!
//! Run: `cargo run --release -p radiosity-core --example codec_error` (prints the table and writes it to
//! `core/examples/codec_error.md`).
//!
//! Scene: the closed cube of `common` (`K x K` patches per face, point-to-point form factors).

mod common;

use common::{rel_l2, Cube, Report};
use radiosity_core::{Config, FfCodec, Outcome, OwnedBuffers, PatchSpec, Solver, Table};

const K: usize = 8;

#[derive(Default)]
struct Kahan {
    sum: f32,
    carry: f32,
}

impl Kahan {
    fn add(&mut self, v: f32) {
        let y = v - self.carry;
        let t = self.sum + y;
        self.carry = (t - self.sum) - y;
        self.sum = t;
    }
}
const RHO: f32 = 0.7;

fn main() {
    let cube = Cube::new(K);
    let Cube { n, area, ref row_start, ref receiver, ref value } = cube;
    let (row_start, receiver, value) = (row_start.as_slice(), receiver.as_slice(), value.as_slice());
    // Reference: Gauss-Seidel on the f32 rows (gathering through reciprocity: equal areas, F_ij = F_ji
    // is not exact after row scaling, so gather in power form: Phi_i = E_i A + rho sum_j F_ji Phi_j).
    let light = cube.light(K);
    let mut reference = vec![0.0f32; n];
    let mut unshot = vec![0.0f32; n];
    unshot[light] = area;
    reference[light] = area;
    loop {
        let mut moved = 0.0f32;
        for j in 0..n {
            let u = std::mem::take(&mut unshot[j]);
            moved += u;
            for k in row_start[j] as usize..row_start[j + 1] as usize {
                let r = RHO * value[k] * u;
                reference[receiver[k] as usize] += r;
                unshot[receiver[k] as usize] += r;
            }
        }
        if moved < 1e-9 * area {
            break;
        }
    }

    let patches: Vec<PatchSpec> = (0..n)
        .map(|i| PatchSpec {
            area,
            material: 0,
            base_emission: if i == light { [1.0; 3] } else { [0.0; 3] },
            base_irradiance: [0.0; 3],
        })
        .collect();
    let mut report = Report::new(
        "codec_error",
        &format!(
            "The form-factor codecs on a closed cube of {K} x {K} patches per face ({n} patches, {} entries, rho \
             {RHO}, one light): row errors are L1 over a row divided by its sum; the solve error is the relative \
             L2 error of `Phi` against a solve with the unquantized f32 form factors.",
            receiver.len()
        ),
    );
    report.line(
        "| codec | bytes | mean row L1 | max row L1 | max entry rel. (>= max/2^7) | max row-sum deficit | solve rel. L2 |",
    );
    report.line("|---|---|---|---|---|---|---|");
    for (name, codec) in [
        ("FLOAT16 (E4 M12)", FfCodec::FLOAT16),
        ("LINEAR16", FfCodec::LINEAR16),
        ("FLOAT8 (E3 M5)", FfCodec::FLOAT8),
        ("E4 M4 (8-bit)", FfCodec { bits: 8, exponent_bits: 4 }),
        ("E2 M6 (8-bit)", FfCodec { bits: 8, exponent_bits: 2 }),
        ("LINEAR8", FfCodec::LINEAR8),
    ] {
        let bytes = cube.table(&patches, RHO, &[], codec);
        let t = Table::parse(&bytes).unwrap();
        let (mut sum_l1, mut max_l1, mut max_entry, mut max_deficit) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for j in 0..n as u32 {
            let range = t.row(j).unwrap();
            let vals = &value[range.start as usize..range.end as usize];
            let row_max = vals.iter().copied().fold(0.0, f32::max);
            // Row sums by Kahan summation, so the deficit is not swamped by f32 summation error.
            let (mut l1, mut s, mut sd) = (0.0f32, Kahan::default(), Kahan::default());
            for (k, &v) in range.clone().zip(vals) {
                let d = t.entry(j, k).unwrap().1.to_f32();
                l1 += (d - v).abs();
                s.add(v);
                sd.add(d);
                if v >= row_max / 128.0 {
                    max_entry = max_entry.max((d - v).abs() / v);
                }
            }
            let (s, sd) = (s.sum, sd.sum);
            sum_l1 += l1 / s;
            max_l1 = max_l1.max(l1 / s);
            max_deficit = max_deficit.max((s - sd) / s);
        }
        // Solve with the core solver (f32 path) to a tight tolerance.
        let mut store = OwnedBuffers::<f32>::for_table(&t);
        let buffers = store.buffers();
        let mut solver = Solver::new(&t, buffers, Config { tolerance: 1e-9 * area, overshoot: 0 }).unwrap();
        while !matches!(solver.step(100_000), Outcome::Converged { .. }) {}
        let power: Vec<f32> = (0..n as u32).map(|i| solver.power(i).unwrap()[0]).collect();
        report.line(&format!(
            "| {name} | {} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
            bytes.len(),
            sum_l1 / n as f32,
            max_l1,
            max_entry,
            max_deficit,
            rel_l2(&power, &reference)
        ));
    }
    report.write();
}
