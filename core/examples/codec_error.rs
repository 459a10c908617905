//! Measures the form-factor codecs on a closed cube: per-row error, table size, and the error each codec
//! causes in a solve (against a solve with the unquantized f32 form factors).
//!
//! Run: `cargo run --release -p radiosity-core --example codec_error`
//!
//! Scene: the inside of a unit cube, `K x K` square patches per face. Form factors by the point-to-point
//! approximation `F_ij = cos_i cos_j A_j / (pi r^2)` between patch centres (no occlusion in a convex box),
//! each row then scaled to sum to 1 (the box is closed). The approximation is crude next to the edges, but
//! gives rows with the spread of magnitudes real rows have (1e-5 .. 1e-1), which is what the codecs see.

use radiosity_core::{
    write_table, Config, FfCodec, Outcome, OwnedBuffers, PatchSpec, RowsSpec, Solver, Table, TableSpec,
};

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

fn cube() -> (Vec<[f32; 3]>, Vec<[f32; 3]>, f32) {
    let mut centre = Vec::new();
    let mut normal = Vec::new();
    let h = 1.0 / K as f32;
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            for a in 0..K {
                for b in 0..K {
                    let mut c = [0.0; 3];
                    c[axis] = side;
                    c[(axis + 1) % 3] = (a as f32 + 0.5) * h;
                    c[(axis + 2) % 3] = (b as f32 + 0.5) * h;
                    let mut nrm = [0.0; 3];
                    nrm[axis] = if side == 0.0 { 1.0 } else { -1.0 };
                    centre.push(c);
                    normal.push(nrm);
                }
            }
        }
    }
    (centre, normal, h * h)
}

fn main() {
    let (centre, normal, area) = cube();
    let n = centre.len();
    let mut row_start = vec![0u32];
    let mut receiver = Vec::new();
    let mut value = Vec::new();
    for i in 0..n {
        let mut row = Vec::new();
        for j in 0..n {
            let d = [0, 1, 2].map(|k| centre[j][k] - centre[i][k]);
            let r2: f32 = d.iter().map(|x| x * x).sum();
            let ci: f32 = (0..3).map(|k| normal[i][k] * d[k]).sum::<f32>() / r2.sqrt();
            let cj: f32 = -(0..3).map(|k| normal[j][k] * d[k]).sum::<f32>() / r2.sqrt();
            if i != j && ci > 0.0 && cj > 0.0 {
                row.push((j as u32, ci * cj * area / (std::f32::consts::PI * r2)));
            }
        }
        let s: f32 = row.iter().map(|x| x.1).sum();
        for (j, f) in row {
            receiver.push(j);
            value.push(f / s * (1.0 - 1e-6));
        }
        row_start.push(receiver.len() as u32);
    }
    // Reference: Gauss-Seidel on the f32 rows (gathering through reciprocity: equal areas, F_ij = F_ji
    // is not exact after row scaling, so gather in power form: Phi_i = E_i A + rho sum_j F_ji Phi_j).
    let light = n - K * K / 2 - K / 2; // a patch near the middle of the last face
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
    println!("cube {K}x{K} per face: {n} patches, {} entries, rho {RHO}", receiver.len());
    println!(
        "| codec | bytes | mean row L1 rel. error | max row L1 rel. error | max entry rel. error (>= row max / 2^7) | max row-sum deficit | solve rel. L2 error |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (name, codec) in [
        ("FLOAT16 (E4 M12)", FfCodec::FLOAT16),
        ("LINEAR16", FfCodec::LINEAR16),
        ("FLOAT8 (E3 M5)", FfCodec::FLOAT8),
        ("E4 M4 (8-bit)", FfCodec { bits: 8, exponent_bits: 4 }),
        ("E2 M6 (8-bit)", FfCodec { bits: 8, exponent_bits: 2 }),
        ("LINEAR8", FfCodec::LINEAR8),
    ] {
        let spec = TableSpec {
            patches: &patches,
            materials: &[[RHO; 3]],
            groups: &[],
            rows: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &value },
            codec,
            base_solved: false,
            fingerprint: 0,
            transfer: None,
            state: None,
        };
        let mut bytes = vec![0u8; radiosity_core::required_len(&spec).unwrap()];
        write_table(&spec, &mut bytes).unwrap();
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
        let (mut num, mut den) = (0.0f32, 0.0f32);
        for (i, r) in reference.iter().enumerate() {
            let p = solver.power(i as u32).unwrap()[0];
            num += (p - r) * (p - r);
            den += r * r;
        }
        println!(
            "| {name} | {} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
            bytes.len(),
            sum_l1 / n as f32,
            max_l1,
            max_entry,
            max_deficit,
            (num / den).sqrt()
        );
    }
}
