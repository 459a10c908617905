//! `radiosity-core`: the device side of the radiosity toolkit.
//!
//! `no_std`, no `alloc`, no `unsafe`, no clock, no `f64`, and no panic on any input. The host writes a table
//! with this crate's writer; the device parses it in place (it stays in flash) and relights the scene with
//! bounded progressive-refinement shooting, a fixed number of work units per frame.
//!
//! # Layers and module map
//! Like smoltcp's wire -> storage -> socket -> iface, each layer uses only the ones before it (no module
//! imports one after it; `python3 ../shared/tools/modcycles.py core/src` checks for cycles):
//!
//! | layer | modules | what lives there | a change of this kind goes here |
//! |---|---|---|---|
//! | 0. checksum | [`crc`] | CRC-32 | |
//! | 1. codecs | [`codec`] (`ff`, `radiometric`, [`codec::transfer`]) | form-factor, reflectance, emission and transfer-response codes, their error bounds, the writer's row rounding | a new code or quantizer |
//! | 2. format | [`format`](mod@format) (`layout`, `error`, `parse`, `view`, [`format::write`]) | the byte layout (`docs/format.md`), [`Table::parse`] (the one checked constructor: after it succeeds no accessor panics), read views ([`Row`]), [`write_table`] | a new section or field (and a version bump) |
//! | 3. arithmetic | [`scalar`] | [`Scalar`] (sealed): `f32` and [`Fixed`] | a new number type |
//! | 4. static base | [`base`] | [`static_radiosity`]: `E_s + rho G_s`, for the solver and the transfer relight | |
//! | 5. solver | [`solver`] (`buffers`, `config`, state in `mod`, `selection`, `shoot`, `sweep`, `relight`) | [`Solver`] holding its [`Table`], buffers sized by [`BufferSizes::of`] (`OwnedBuffers` on a host, `std` feature, [`StaticBuffers`] on a device), bounded steps ([`Solver::step`], [`Solver::step_gauss_seidel`], [`Solver::step_jacobi`]) reporting an [`Outcome`], relighting ([`Solver::set_light`], [`Solver::set_reflectance`]) | a new step, selection rule or state |
//! | 5b. hierarchical solver | [`hier`] (`buffers`, state and steps in `mod`) | [`HierSolver`] over a [`HierTable`] (format version 5): incident power per leaf, unshot power per node, pending power and reflected power per inner node, shots in rounds that leave power pending at inner receivers (leaf receivers take it at once), one sweep over the tree per round (chain sums down and subtree sums up on a path of [`SweepFrame`]s), leaf power computed on readout, bounded resumable steps; buffers by [`HierBufferSizes::of`]. Uses the solver's [`Config`], [`Outcome`] and [`SolverError`] | hierarchical stepping |
//! | 6. transfer relight | [`transfer`] | [`relight_transfer`]: `B = B_static + sum_g I_g T_g` in one bounded pass, the peer of shooting | |
//!
//! The solver holds a copy of the parsed [`Table`] (a handful of slices into the blob, which stays in
//! flash) for its lifetime, so no call can pass another table and no call pays for checking that it did.
//!
//! # Physics conventions (units)
//! - Diffuse surfaces only, static geometry, RGB. Patch `i`: area `A_i` (scene units squared), reflectance
//!   `rho_i` per channel with `0 <= rho < 1`, emission `E_i` (radiant exitance, W/m^2), radiosity `B_i` (W/m^2).
//! - Form factor `F_ij`: the fraction of the power leaving patch `i` that reaches patch `j` directly. Rows sum
//!   to at most 1 (exactly 1 in a closed scene); reciprocity `A_i F_ij = A_j F_ji`.
//! - Radiosity equation `B_i = E_i + rho_i sum_j F_ij B_j`, i.e. `(I - R F) B = E`.
//! - The solver works in power units `Phi_i = B_i A_i` (W when areas are in m^2). Shooting (progressive
//!   refinement, Cohen, Chen, Wallace, Greenberg, SIGGRAPH 1988; a Southwell iteration) distributes one
//!   patch's unshot power: `dPhi_i += rho_i F_ji dPhi_j`. So the table stores **shooter rows**: row `j` lists
//!   the receivers `i` with `F_ji`, the host's `F` matrix as is. A shot reads one row and no areas.
//! - The solver also keeps the incident power `H_i = sum_j F_ji Phi_j` received so far, so that
//!   `Phi_i = E_i A_i + rho_i H_i` holds at every moment; a reflectance edit injects `(rho' - rho) H_i`.
//! - Linearity: `B = B_static + sum_g intensity_g T_g` with `T_g` the response to light group `g` at unit
//!   intensity. A light group's member emission is stored at unit intensity; the run-time emission of a member is
//!   `intensity (RGB) * unit emission (RGB)`.
//!
//! # Static base
//! Lights that never change are folded into a per-patch **static base**: static emission `E_s` (W/m^2) and
//! static irradiance `G_s = sum_j F_ij B_static_j` (W/m^2, the light arriving from the static solution).
//! The solver starts from `Phi = (E_s + rho G_s) A`, `H = G_s A`. If the table says the base is solved
//! (`base_solved`, the host computed `G_s` with its f64 reference), nothing static is unshot: static light costs
//! no work at run time, and a reflectance edit still sees the static light through `H`. If not, `G_s` should be
//! zero and the static power starts as unshot power and is shot by the device.
//!
//! # Run-time state
//! Patches that no dynamic light can reach carry no run-time state. A table lists the patches that do, its
//! **slots**: `state_count` (`s <= n`) patches, slot `k` being the `k`-th of them in ascending patch order
//! ([`Table::slot_patch`], [`Table::slot_of`]). Only slots have form-factor rows, entries name receiver
//! *slots*, and the solver's buffers and selection are sized by `s`: the shooting loop indexes them by
//! slot directly, with the slot's material read from a slot-ordered section (no map lookup per entry). A patch
//! without state shows its static base `E_s + rho G_s` ([`static_radiosity`]), so leaving patches out requires
//! a solved base (`base_solved`); the writer refuses otherwise ([`WriteError::StateNeedsSolvedBase`]) and a
//! table with an unsolved base must give every patch state. Every light-group member has state.
//!
//! The host gives a patch state if it is a member of a dynamic light group, or if it reflects (nonzero
//! reflectance in some channel) and receives a stored entry from a patch with state. So a row of a slot
//! loses only entries to stateless receivers black in every channel, which reflect nothing: the answer is
//! unchanged for the table's reflectances. A reflectance edit ([`Solver::set_reflectance`]) acts on the
//! patches with state; a stateless patch shows `E_s + rho' G_s` with the new reflectance (its reflection of
//! the static light) and nothing more. When every patch has state (`s = n`) the map sections are absent:
//! slot = patch, and the format costs one header varint more than without the feature.
//!
//! # Transfer basis
//! With reflectances fixed, radiosity is linear in the light-group intensities: `B = B_static + sum_g I_g T_g`
//! (crate docs above, "Linearity"). A table may carry the quantized responses `T_g` (W/m^2 per unit intensity,
//! RGB, every patch and light group) as an optional section; `B_static` is the solved static base,
//! `E_s + rho G_s` per patch (so a transfer section requires `base_solved`; [`static_radiosity`] decodes it).
//! Entry points:
//! - [`relight_transfer`]`::<S>(table, intensity: &[[S; 3]], out: &mut [[S; 3]]) -> Result<u32, TransferError>`
//!   writes `B` of every patch into the caller's `out` (f32 or [`Fixed`], no allocation) and returns the work
//!   units spent, [`transfer_cost`]`(table) = patches x (groups + 1)` (one unit per patch for the static base,
//!   one per patch and group: an RGB code triple decoded and three multiply-adds, like one form-factor entry).
//!   [`relight_transfer_range`] relights a run of elements into a smaller buffer (a light map streamed in
//!   chunks), bit for bit the same values.
//! - [`Table::has_transfer`], [`Table::transfer_exponent`], [`Table::transfer_code`],
//!   [`Table::transfer_response`] to read the section; the writer takes it as [`TableSpec::transfer`].
//!
//! Quantization: core's 16-bit small float ([`FfCodec::FLOAT16`]) under a power-of-two scale `2^K` per
//! group and channel (`K = floor(log2)` of the group's largest response), rounded to nearest, so each response
//! is within `max(2^-13 T, 2^(K - 27))` of the host's value: relative `1.2e-4` down to `2^-14` of the group's
//! brightest patch. A relight is within `sum_g |I_g| max(2^-13 T_g, 2^(K_g - 27))` plus the static base's code
//! error plus arithmetic rounding of the exact `B_static + sum_g I_g T_g` (details and
//! the arithmetic terms in [`transfer`]). The basis holds for the table's reflectances only: after
//! [`Solver::set_reflectance`], or with many groups (the section grows as `patches x groups`), shoot.
//!
//! # Table layout
//! The byte layout is specified in `docs/format.md`, rendered in [`format`](mod@format)'s docs: flat tables
//! (patch rows, [`Table`]) are format version 3, hierarchical tables (a node tree in preorder and links grouped
//! by sender, [`HierTable`], written by [`write_hier_table`]) are version 5. Each reader refuses the other's
//! version naming the right one.
//!
//! # Hierarchical tables and solver
//! A hierarchical table stores a node tree (Hanrahan, Salzman, Aupperle 1991): leaves are the elements whose
//! radiosity is the answer, inner nodes group them, and a link `(s, r, F_sr)` carries the fraction of the power
//! leaving `s`'s subtree that reaches node `r` (shooter factors, as flat rows). [`HierSolver`] shoots per node:
//! see [`hier`] for the scheme, its convergence bound (the chain bound of `docs/format.md`) and its work units.
//! A host with two-way links `(a, b, f_ab, f_ba)` whose factors are receiver-averaged (`f_ab`: the irradiance
//! gathered at `a` per unit radiosity of `b`, averaged over `a`) writes sender `b`, receiver `a`,
//! `F = f_ab A_a / A_b`, and sender `a`, receiver `b`, `F = f_ba A_b / A_a` (reciprocity `A_r F_rs = A_s F_sr`):
//! the table's system is then the host's gathering system exactly, whether or not the two estimates are
//! reciprocal. Hierarchical tables have no state map (every leaf has state); they may carry a transfer basis
//! per leaf, laid out as the flat table's ([`HierTable::transfer`]).
//!
//! # Cost model: work units
//! A work unit is one of: one form-factor entry applied (decode, three multiply-adds into power, unshot and
//! incident power, and for shooting the comparison of the receiver's unshot magnitude with its block's winner),
//! one slot scanned when a selection block is rebuilt, one block winner scanned when selecting, one row visit or
//! patch visit of a sweep. Each is a small constant number of instructions on any platform, so instructions
//! are linear in units. The counts do not depend on the platform or the arithmetic path.
//! - Shooting ([`Solver::step`]): the shooter is the slot with the largest unshot magnitude `|r| + |g| + |b|`
//!   (ties to the lower slot). Here and in the sweeps, `n` and "patch" count the patches with run-time state
//!   only (the state count `s`). The slots are cut into blocks of `B` consecutive slots (`B` the power of two
//!   at or above `sqrt(n)`), and the caller's selection buffer ([`Buffers::selection`], [`selection_len`] entries) holds each block's
//!   winner. Building it costs `n` units (inside step budgets, resumable block by block); a selection scans the
//!   `ceil(n / B)` winners; a shot costs 1 unit plus a rescan of the shooter's block (`<= B`); each entry costs
//!   1 unit, plus a rescan of its block when the receiver was the block's winner and moved towards zero in some
//!   channel (only possible with overshooting or after a light was dimmed). So about `2 sqrt(n)` units per
//!   shot and 1 per entry: receivers are increasing within a row, and the block winner being compared stays
//!   in registers while the row stays in its block. An action starts only if its worst case (an entry with a
//!   rescan: `B + 1`) fits in what is left of the budget, and a shot longer than the budget is split: the next
//!   step resumes the row where it stopped. So a step never spends more than its budget.
//! - Gauss-Seidel and Jacobi sweeps: 1 unit per row visit, 1 per entry, 1 per patch in the end-of-sweep scan
//!   (plus 1 per patch to clear Jacobi's scratch buffer).
//! - Outside the budget, reported as return values where they depend on the scene: [`Solver::set_light`]
//!   (members plus block rescans), [`Solver::set_reflectance`] (slots scanned plus block rescans); and
//!   [`Solver::new`], [`Solver::reset`], [`Solver::ambient`], which are `O(patches + members)`.
//! - Transfer relight ([`relight_transfer`]): `patches x (groups + 1)` units, outside any budget, not
//!   resumable (its cost is known from the counts).
//!
//! # Error bounds
//! - Form factors (see [`codec`]): the default [`FfCodec::FLOAT16`] (4 exponent and 12 mantissa bits under a
//!   per-row power-of-two scale) has relative error `< 2^-12` (2.4e-4) for entries `>= row max / 2^14`;
//!   [`FfCodec::FLOAT8`] (3 + 5 bits) `< 2^-5` (3.1%) for entries `>= row max / 2^6`. Rounding keeps every
//!   row's decoded sum `<=` its true sum and `<= 1`; the deficit is less than one code step plus the losses of
//!   entries smaller than half a code step, which are only rounded down (a step is never added where it would
//!   more than double an entry).
//!   The rounding is largest remainder under that constraint, with no round-down bias ([`codec`], "Row-sum
//!   rounding").
//! - Reflectance: absolute error `<= 2^-17`. Emission and irradiance: relative `<= 2^-11` in
//!   `[9.3e-10, 8.6e9]` W/m^2. A light's emission code error carries over, at that relative size, to every
//!   patch the light reaches; where a form-factor table's answer must be closer than `2^-11`, the emission code
//!   is the limit, not the form-factor codes.
//! - Convergence: decoded rows sum to `<= 1` and reflectances are `< 1`, so `R F` has row sums `< 1` and
//!   shooting converges. [`Outcome::Converged`] means every patch's unshot magnitude is `<= tolerance`; the
//!   remaining error per patch is at most `n * tolerance / ((1 - rho_max) A_min)`.
//! - Arithmetic: `f32`, or [`Fixed`] (Q32.32 in `i64`, integer only, saturating; range about `+-2.1e9` power
//!   units, resolution `2.3e-10`, products rounded to nearest), chosen by the solver's type parameter. See
//!   [`scalar`] for the fixed-point convergence condition on the tolerance. The hierarchical solver's link
//!   loops stop it with `NotFinite` at half that range, `+-1.07e9` (module docs of [`hier`], "Range").
//!
//! Solver cost and arithmetic error by method (shooting, with and without overshoot, Gauss-Seidel, Jacobi;
//! `f32` and fixed point; warm starts after relighting) are measured by the `methods` example on a closed cube,
//! and the form-factor codecs' row and solve errors by the `codec_error` example; each writes its tables to a
//! generated file, `core/examples/methods.md` and `core/examples/codec_error.md`
//! (`cargo run --release -p radiosity-core --example methods`, likewise `codec_error`).
//!
//! Shooting costs about one unit per entry plus `2 sqrt(n)` per shot, so in a dense closed scene with a single
//! light plain shooting and Gauss-Seidel sweeps cost about the same, and shooting with overshooting less.
//! Shooting's further advantage is its order: the largest unshot power goes first, so after a light change the
//! first budgets carry the changed light's direct contribution. Fixed point's error on the cube is the Q32.32
//! resolution against the small powers of a unit cube, with the tolerance at its floor.
//!
//! With an absolute tolerance the work to re-converge after a relight grows with `log(change / tolerance)`, so a
//! warm start saves most when the change is small against the scene's light; its value on the device is that
//! every frame in between shows the old solution plus the largest corrections, never a blank start.
//!
//! The small-float codecs beat the block-linear ones on per-entry and per-row error at both widths (the
//! block-linear codes lose small entries next to a large one); at 8 bits E3 M5 has the smallest solve error, so
//! FLOAT16 and FLOAT8 are the defaults.
//!
//! # How the host calls the writer
//! ```
//! use radiosity_core::{
//!     required_len, write_table, Config, FfCodec, GroupSpec, MemberSpec, Outcome, OwnedBuffers, PatchSpec,
//!     RowsSpec, Solver, Table, TableSpec,
//! };
//!
//! // Two patches facing each other: areas 1 and 2, F_01 = 0.4, F_10 = 0.2 (A_0 F_01 = A_1 F_10).
//! let patch = |area| PatchSpec { area, material: 0, base_emission: [0.0; 3], base_irradiance: [0.0; 3] };
//! let patches = [patch(1.0), patch(2.0)];
//! let lamp = [MemberSpec { patch: 0, emission: [1.0, 1.0, 1.0] }];
//! let groups = [GroupSpec { id: 0x6c61_6d70, default_intensity: [1.0; 3], members: &lamp }];
//! let spec = TableSpec {
//!     patches: &patches,
//!     materials: &[[0.5, 0.5, 0.5]],
//!     groups: &groups,
//!     // Shooter rows (CSR): row j lists receivers i with F_ji.
//!     rows: RowsSpec { row_start: &[0, 1, 2], receiver: &[1, 0], form_factor: &[0.4, 0.2] },
//!     codec: FfCodec::FLOAT16,
//!     base_solved: false,
//!     fingerprint: 0,
//!     transfer: None,
//!     // Every patch keeps run-time state (the base is not solved).
//!     state: None,
//! };
//! let mut blob = vec![0u8; required_len(&spec)?];
//! let written = write_table(&spec, &mut blob)?;
//! assert_eq!(written, blob.len());
//!
//! // The device side: parse in place, solve in fixed buffers with a per-frame budget.
//! let table = Table::parse(&blob)?;
//! // Buffers sized by the table (`BufferSizes::of`): `OwnedBuffers` on a host, `StaticBuffers` on a device.
//! let mut store = OwnedBuffers::<f32>::for_table(&table);
//! let mut solver = Solver::new(&table, store.buffers(), Config { tolerance: 1e-7, overshoot: 0 })?;
//! while let Outcome::BudgetSpent { .. } = solver.step(16) {}
//! let b0 = solver.radiosity(0).unwrap()[0];
//! // By hand: B_0 = 1 / (1 - 0.5 * 0.5 * 0.4 * 0.2) = 1.0204...
//! assert!((b0 - 1.0 / 0.98).abs() < 1e-3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod base;
pub mod codec;
pub mod crc;
pub mod format;
pub mod hier;
pub mod scalar;
pub mod solver;
pub mod transfer;

pub use base::static_radiosity;
pub use codec::{FfCodec, Frac};
pub use format::write::{
    required_len, write_table, GroupSpec, MemberSpec, PatchSpec, RowsSpec, TableSpec, WriteError,
};
pub use format::{
    group_id, hier_required_len, write_hier_table, HierMember, HierSpec, HierTable, NodeSpec, Row,
    SectionSizes, Table, TableError, TreeFault, FORMAT_VERSION, HIER_FORMAT_VERSION, MAGIC,
};
#[cfg(any(test, feature = "std"))]
pub use hier::HierOwnedBuffers;
pub use hier::{
    hier_convergence_floor, HierBufferSizes, HierBuffers, HierSolver, HierStaticBuffers, SweepFrame,
};
pub use scalar::{Fixed, Scalar};
#[cfg(any(test, feature = "std"))]
pub use solver::OwnedBuffers;
pub use solver::{
    convergence_floor, selection_len, BufferSizes, Buffers, Config, NoProgressReason, Outcome, Solver,
    SolverError, StaticBuffers,
};
pub use transfer::{
    relight_transfer, relight_transfer_range, transfer_cost, TransferError, TransferTable,
    TRANSFER_GROUP_BLOCK,
};
