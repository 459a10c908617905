//! Shared helpers for the integration tests: an owned scene that turns into a `TableSpec`, and solvers with
//! owned buffers.
#![allow(dead_code)]

use radiosity_core::{
    write_table, Config, FfCodec, Fixed, GroupSpec, MemberSpec, OwnedBuffers, PatchSpec, RowsSpec, Scalar,
    Solver, Table, TableSpec, WriteError,
};

/// An owned scene description (what the host would hold before writing a table).
#[derive(Clone, Debug)]
pub struct Scene {
    pub patches: Vec<PatchSpec>,
    pub materials: Vec<[f32; 3]>,
    /// (id, default intensity, members)
    pub groups: Vec<(u32, [f32; 3], Vec<MemberSpec>)>,
    /// Shooter rows per slot: `rows[j]` = receiver slots `(i, F_ji)`, sorted (slot = patch without `state`).
    pub rows: Vec<Vec<(u32, f32)>>,
    /// Patches with run-time state, ascending (`None`: every patch).
    pub state: Option<Vec<u32>>,
    pub codec: FfCodec,
    pub base_solved: bool,
    pub fingerprint: u64,
    /// Transfer basis, patch-major (`[i * groups + g]`), if any.
    pub transfer: Option<Vec<[f32; 3]>>,
}

impl Scene {
    pub fn new(n: usize) -> Scene {
        Scene {
            patches: vec![
                PatchSpec {
                    area: 1.0,
                    material: 0,
                    base_emission: [0.0; 3],
                    base_irradiance: [0.0; 3]
                };
                n
            ],
            materials: vec![[0.5; 3]],
            groups: Vec::new(),
            rows: vec![Vec::new(); n],
            codec: FfCodec::FLOAT16,
            base_solved: false,
            fingerprint: 0,
            transfer: None,
            state: None,
        }
    }

    /// Writes the table through core's writer into `out`, returning the writer's answer (its error included).
    pub fn write_into(&self, out: &mut [u8]) -> Result<usize, WriteError> {
        let mut row_start = vec![0u32];
        let mut receiver = Vec::new();
        let mut form_factor = Vec::new();
        for r in &self.rows {
            for &(i, f) in r {
                receiver.push(i);
                form_factor.push(f);
            }
            row_start.push(receiver.len() as u32);
        }
        let groups: Vec<GroupSpec<'_>> = self
            .groups
            .iter()
            .map(|(id, d, m)| GroupSpec { id: *id, default_intensity: *d, members: m })
            .collect();
        let spec = TableSpec {
            patches: &self.patches,
            materials: &self.materials,
            groups: &groups,
            rows: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
            codec: self.codec,
            base_solved: self.base_solved,
            fingerprint: self.fingerprint,
            transfer: self.transfer.as_deref(),
            state: self.state.as_deref(),
        };
        write_table(&spec, out)
    }

    /// The table's bytes; panics (test failure) if the writer refuses the scene.
    pub fn write(&self) -> Vec<u8> {
        let mut out = vec![0u8; self.required_len()];
        let written = self.write_into(&mut out).expect("write_table");
        assert_eq!(written, out.len());
        out
    }

    /// The bytes the writer needs for this scene; panics (test failure) if it refuses it.
    fn required_len(&self) -> usize {
        // An empty buffer makes the writer report the length it needs.
        match self.write_into(&mut []) {
            Err(WriteError::BufferTooSmall { needed, .. }) => needed,
            other => panic!("required_len: {other:?}"),
        }
    }
}

/// Owned solver buffers (core's `OwnedBuffers`), with a shorthand for a solver on them.
pub type Store<S> = OwnedBuffers<S>;

/// A solver for `t` on `store`'s buffers; panics (test failure) if the buffers do not fit.
pub fn solver<'b, S: Scalar>(store: &'b mut Store<S>, t: &Table<'b>, config: Config<S>) -> Solver<'b, S> {
    Solver::new(t, store.buffers(), config).expect("buffers sized from the table")
}

/// Steps until converged; panics (test failure) if it does not converge within `max_units`.
pub fn converge<S: Scalar>(s: &mut Solver<'_, S>, per_step: u32, max_units: u64) -> u64 {
    let mut total = 0u64;
    loop {
        let o = s.step(per_step);
        assert!(o.used() <= per_step, "budget {per_step} exceeded: {o:?}");
        total += u64::from(o.used());
        match o {
            radiosity_core::Outcome::Converged { .. } => return total,
            radiosity_core::Outcome::BudgetSpent { .. } => {}
            other => panic!("no progress: {other:?}"),
        }
        assert!(total <= max_units, "not converged within {max_units} units");
    }
}

/// Radiosity of every patch as f32 triples.
pub fn radiosities<S: Scalar>(s: &Solver<'_, S>, t: &Table<'_>) -> Vec<[f32; 3]> {
    (0..t.patch_count()).map(|i| s.radiosity(i).unwrap().map(|x| x.to_f32())).collect()
}

/// Asserts `|a - b| <= tol` with both values and the difference in the message.
#[track_caller]
pub fn assert_close(what: &str, actual: f32, expected: f32, tol: f32) {
    let d = (actual - expected).abs();
    assert!(d <= tol, "{what}: actual {actual}, expected {expected}, |diff| {d} > allowed {tol}");
}

/// Fixed-point resolution, as a tolerance unit.
pub const FIXED_EPS: f32 = 1.0 / 4_294_967_296.0;

/// The arithmetic error term of each path (see `solver.rs`'s module docs for the derivation).
pub trait Arith: Scalar {
    /// Arithmetic error of `B` after `shots` shots.
    fn arith(b: f32, shots: u32, rho_max: f32, area_min: f32) -> f32;
    /// Representation error of an input value (`from_f32`).
    fn input(v: f32) -> f32;
}

impl Arith for f32 {
    fn arith(b: f32, shots: u32, rho_max: f32, _area_min: f32) -> f32 {
        3.0 * f32::EPSILON / 2.0 * (shots as f32 + 1.0 / (1.0 - rho_max)) * b.abs()
    }
    fn input(_v: f32) -> f32 {
        0.0
    }
}

impl Arith for Fixed {
    fn arith(_b: f32, shots: u32, rho_max: f32, area_min: f32) -> f32 {
        2.0 * FIXED_EPS * shots as f32 / ((1.0 - rho_max) * area_min)
    }
    fn input(_v: f32) -> f32 {
        FIXED_EPS / 2.0
    }
}

/// The truncation error term: `n * tol / ((1 - rho_max) A_min)` (see `solver.rs`'s module docs).
pub fn truncation(n: usize, tol: f32, rho_max: f32, area_min: f32) -> f32 {
    n as f32 * tol / ((1.0 - rho_max) * area_min)
}

/// The solver tolerance of the hand-made tests (power units).
pub const TOL: f32 = 1e-6;

/// Plain shooting at [`TOL`].
pub fn config<S: Scalar>() -> Config<S> {
    Config { tolerance: S::from_f32(TOL), overshoot: 0 }
}

pub fn cold<S: Arith>(scene: &Scene) -> (Vec<[f32; 3]>, u32) {
    let bytes = scene.write();
    let t = Table::parse(&bytes).unwrap();
    let mut store = Store::<S>::for_table(&t);
    let mut solver = solver(&mut store, &t, config());
    converge(&mut solver, 50, 10_000_000);
    (radiosities(&solver, &t), solver.shots())
}

pub fn compare(what: &str, a: &[[f32; 3]], b: &[[f32; 3]], tol: impl Fn(f32) -> f32) {
    for (x, y) in a.iter().zip(b) {
        for c in 0..3 {
            assert_close(what, x[c], y[c], tol(y[c]));
        }
    }
}
