//! Baking: turns patches, their lighting and an f64 form-factor matrix into a table the device runs.
//!
//! Steps, in order ([`bake`]):
//!
//! 1. **Sparsify** ([`sparsify`]). Entry `F_ij` of shooter row `i` carries the fraction `F_ij` of the power
//!    leaving patch `i` to receiver `j`; that is the *energy* of an entry, measured by `F` alone, not
//!    `rho_j F_ij` (a black receiver's entries are kept because a run-time reflectance edit may make it
//!    reflect). With threshold `t`, an entry is dropped only if two budgets allow it: its row may lose at most
//!    the fraction `t` of the energy it transports (`d_i <= t s_i`, `s_i` the row sum), and its receiver at most
//!    the fraction `t` of the power it receives under uniform radiosity (`sum_i A_i dF_ij <= t sum_i A_i F_ij`).
//!    The row budget alone is not enough: dropping the same small receiver from many rows (a patch lit only
//!    through weak links, or ties in a uniform row) would leave it dark on the device although no row lost
//!    much. Entries are visited from the least power `A_i F_ij` up. `t = 0` drops nothing (except entries that
//!    are exactly zero, which carry nothing). Rows are never renormalized: the dropped energy is reported per
//!    row (max, mean, largest fraction of a row and of a receiver), in total (the sum of all dropped `F_ij`)
//!    and area-weighted (`sum_i A_i d_i / sum_i A_i s_i`, the fraction of all transported power under uniform
//!    radiosity). Both budgets are independent of the lighting (lights change at run time), so a dim patch lit
//!    mostly through weak links from a bright light can lose more than `t` of its actual irradiance: on a
//!    random 60-patch scene at `t = 1e-3` the area-weighted relative L2 error is 1e-4 but the worst patch is
//!    off by 11% (`error_grows_with_threshold_and_fewer_bits` in `host/tests/bake.rs` prints the numbers). The
//!    report's per-patch maximum shows it.
//! 2. **Static base.** Static lights are solved in f64 by the reference solver on the sparsified matrix and
//!    stored as static emission `E_s` and static irradiance `G_s`, with `base_solved = true` (core's crate
//!    docs, "Static base"), so static light costs the device no work.
//!    The device shoots (`H_i += F_ji Phi_j`), so what it converges to solves `B = E + R F~ B` with the
//!    *shooting form* `F~_ij = A_j F_ji / A_i` of the stored rows ([`shooting_form`]). With exact reciprocity
//!    `F~ = F`; after sparsification (or with estimated form factors) they differ slightly, so the base is
//!    solved on `F~` and `G_s_i = sum_j F~_ij B_s_j = (1 / A_i) sum_j F_ji A_j B_s_j`: this is exactly a fixed
//!    point of the device's shooting, so the base stays converged.
//! 3. **Dynamic light groups** become core's light groups: members are the patches of the group with their
//!    emission at unit intensity, the group's default intensity, and an id [`group_id`] (FNV-1a of the name).
//! 4. **Quantize and write** with core's codec ([`codec_for_bits`]: 16 -> `FLOAT16`, 8 -> `FLOAT8`),
//!    [`required_len`] and [`write_table`]: the rows of the patches with run-time state only (step 5), their
//!    receivers as slots.
//! 5. **Reachability** (computed before writing). A patch needs run-time state if it is a member of a dynamic
//!    light group, or if its reflectance is nonzero in some channel and it receives a stored entry from a
//!    patch that needs state (a black receiver's radiosity never changes). Only these patches get state in the
//!    table (core's crate docs, "Run-time state"): core's solver sizes its buffers and selection by their
//!    count, and every other patch shows its solved static base. The rows of the patches with state lose their
//!    entries to stateless receivers, which are black in every channel and reflect nothing, so the answer is
//!    unchanged for the baked reflectances; the report counts them ([`RuntimeState`]). Reachability uses the
//!    baked reflectances: a run-time reflectance edit cannot make a black receiver respond to dynamic light.
//!    When every patch is reachable the table gives every patch state and carries no state map.
//! 6. **Error of the bake** on the scene's own lights (every dynamic group at its default intensity), each a
//!    [`metrics::compare`] against the f64 solve of the original matrix (`B = E + R F B`):
//!    `reciprocity` (the shooting form of the original matrix: nonzero only if `F` is not exactly reciprocal),
//!    `sparsify` (the shooting form of the sparsified matrix, f64) and `sparsify_quantize` (everything decoded
//!    back from the written table with [`Table::parse`]: form factors, reflectances, areas, emissions).
//!
//! 7. **Transfer basis** (with [`BakeOptions::transfer`]). The responses `T_g` of every patch to every
//!    dynamic light group at unit intensity are solved in f64 by [`transfer_vectors`] on the same shooting form
//!    of the sparsified matrix as the static base, then quantized by core's writer into the table's transfer
//!    section (core's `transfer` module: per group and channel a power-of-two scale, 16-bit small floats). The report
//!    ([`TransferReport`]) gives the section's bytes and core's f32 relight at the default intensities against
//!    the f64 solve of the original matrix and against the f64 `B_static + sum_g I_g T_g` it was quantized from.
//!
//! The table's header carries [`scene_fingerprint`] of the patches, so a tool holding a table and a scene can
//! tell whether the table was baked from that scene and meshing ([`Table::fingerprint`]).
//!
//! [`Capacities`] are the sizes a firmware build needs for exactly this table.

use std::collections::VecDeque;
use std::fmt;

use radiosity_core::{
    required_len, write_table, BufferSizes, FfCodec, GroupSpec, MemberSpec, PatchSpec, RowsSpec, Table,
    TableSpec,
};
use serde::Serialize;
use thiserror::Error;

use crate::inspect::SectionBytes;
use crate::lighting::PatchLighting;
use crate::metrics::{self, ErrorReport, MetricsError};
use crate::patch::{FormFactorMatrix, Patch};
use crate::reference::{
    solve_many, transfer_vectors, GaussSeidelOptions, LightGroupEmission, Method, Radiosity, RadiositySystem,
    ReferenceError, TransferVectors,
};
use crate::scene::Scene;

/// Default sparsification threshold: each row may lose at most 0.1% of the energy it transports.
pub const DEFAULT_THRESHOLD: f64 = 1e-3;

/// Default slack on row sums of the shooting form `F~` above 1 (see [`BakeOptions::row_sum_tolerance`]).
pub const DEFAULT_ROW_SUM_TOLERANCE: f64 = 1e-4;

/// Settings of a bake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakeOptions {
    /// Sparsification threshold `t` in `[0, 1)`: largest fraction of a row's energy that may be dropped.
    pub threshold: f64,
    /// Form-factor codec (see [`codec_for_bits`]).
    pub codec: FfCodec,
    /// Slack on row sums above 1 allowed in the f64 solves. The shooting form `F~_ij = A_j F_ji / A_i` of an
    /// estimated matrix has row sums above 1 by the reciprocity error; the closed-scene target is
    /// `1e-4`, hence the default.
    pub row_sum_tolerance: f64,
    /// Reference solver; `None` picks [`default_method`].
    pub method: Option<Method>,
    /// Store the transfer basis (core's `transfer` module): the response `T_g` of every patch to every dynamic
    /// light group, solved in f64 on the table's own matrix and quantized, for `B = B_static + sum_g I_g T_g`.
    pub transfer: bool,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            threshold: DEFAULT_THRESHOLD,
            codec: FfCodec::FLOAT16,
            row_sum_tolerance: DEFAULT_ROW_SUM_TOLERANCE,
            method: None,
            transfer: false,
        }
    }
}

/// What a bake needs: patches, their lighting, material reflectances, dynamic group names and form factors.
#[derive(Clone, Debug)]
pub struct BakeInput<'a> {
    /// Patches (area and material are used).
    pub patches: &'a [Patch],
    /// Reflectance per material (RGB, each in `[0, 1)`); `Patch::material` indexes it.
    pub materials: Vec<[f64; 3]>,
    /// Reflectance and emission per patch, with the dynamic light groups.
    pub lighting: &'a PatchLighting,
    /// Name of each dynamic light group, in the order of `lighting.dynamic_groups`.
    pub group_names: Vec<String>,
    /// Form factors `F_ij` (row `i` = shooter), f64.
    pub form_factors: &'a FormFactorMatrix,
}

impl<'a> BakeInput<'a> {
    /// Collects the input from a scene, its patches, their lighting and the form factors.
    #[must_use]
    pub fn from_scene(
        scene: &Scene,
        patches: &'a [Patch],
        lighting: &'a PatchLighting,
        form_factors: &'a FormFactorMatrix,
    ) -> BakeInput<'a> {
        BakeInput {
            patches,
            materials: scene.materials.iter().map(|m| m.reflectance).collect(),
            lighting,
            group_names: lighting
                .dynamic_groups
                .iter()
                .map(|&g| scene.light_groups[g].name.clone())
                .collect(),
            form_factors,
        }
    }
}

/// Why a bake failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum BakeError {
    /// The threshold is not in `[0, 1)`.
    #[error("sparsification threshold {0} not in [0, 1)")]
    BadThreshold(f64),
    /// `--bits` other than 8 or 16.
    #[error("unsupported form-factor width {0} bits (use 16 or 8)")]
    BadBits(u32),
    /// Inputs disagree in length or content.
    #[error("bake input: {0}")]
    Input(String),
    /// Two dynamic light groups hash to the same id.
    #[error("light groups `{0}` and `{1}` have the same id {2:#010x}; rename one")]
    GroupIdCollision(String, String, u32),
    /// The f64 reference solve failed.
    #[error("f64 reference solve ({what}): {source}")]
    Reference {
        /// Which solve.
        what: &'static str,
        /// The solver's error.
        source: ReferenceError,
    },
    /// The codec is too coarse for this scene: a patch's decoded incoming form factors (the shooting form
    /// `A_j F_ji / A_i` of the stored sender rows) sum to far more than 1, because each code step of a sender's
    /// row is multiplied by the sender's area over the receiver's.
    #[error(
        "{bits}-bit form-factor codes are too coarse for this scene: the incoming form factors of patch {patch} \
         (area {area:.3e}) decode to a sum of {sum:.3} (physical: at most 1 + {tolerance:.2e}); \
         senders up to {ratio:.0} times its area multiply each code step by that ratio. Use --bits 16, or mesh \
         so that small patches do not border much larger ones"
    )]
    CodecTooCoarse {
        /// Bits per form-factor code.
        bits: u8,
        /// The receiving patch.
        patch: usize,
        /// Its area.
        area: f64,
        /// Its decoded incoming row sum.
        sum: f64,
        /// The tolerance it exceeds.
        tolerance: f64,
        /// Largest sender area over its area, among its stored senders.
        ratio: f64,
    },
    /// Core's writer rejected the table.
    #[error("writing the table: {0}")]
    Write(radiosity_core::WriteError),
    /// The written table does not parse (a writer bug; never expected).
    #[error("the written table does not parse: {0}")]
    Parse(radiosity_core::TableError),
    /// Core's transfer relight of the written table failed (a writer bug; never expected).
    #[error("transfer relight of the written table: {0}")]
    Transfer(radiosity_core::TransferError),
    /// Error metrics could not be computed.
    #[error("error metrics: {0}")]
    Metrics(#[from] MetricsError),
}

/// The form-factor codec for a code width: 16 -> [`FfCodec::FLOAT16`], 8 -> [`FfCodec::FLOAT8`].
///
/// # Errors
/// [`BakeError::BadBits`] for any other width.
pub fn codec_for_bits(bits: u32) -> Result<FfCodec, BakeError> {
    match bits {
        16 => Ok(FfCodec::FLOAT16),
        8 => Ok(FfCodec::FLOAT8),
        _ => Err(BakeError::BadBits(bits)),
    }
}

/// The table id of a light group: 32-bit FNV-1a of its name (Fowler, Noll, Vo; IETF draft
/// draft-eastlake-fnv), so firmware can refer to a group by a constant derived from its name.
#[must_use]
pub fn group_id(name: &str) -> u32 {
    let mut h: u32 = 0x811c_9dc5;
    for &b in name.as_bytes() {
        h ^= u32::from(b);
        h = h.wrapping_mul(0x0100_0193);
    }
    h
}

/// The scene fingerprint stored in a table's header: 64-bit FNV-1a (Fowler, Noll, Vo; IETF draft
/// draft-eastlake-fnv) over the patch count and, per patch in order, its parent face and material index
/// (`u64` LE) and the f64 bits (LE) of its area, centroid and normal. It identifies the scene and its meshing:
/// any moved, resized, re-meshed or re-materialled patch changes it (up to hash collisions, probability
/// about `2^-64` per pair of scenes). Reflectance and emission values are not included: they are in the
/// table itself. `-0.0` is hashed as `0.0`, so the sign of a zero coordinate does not matter.
#[must_use]
pub fn scene_fingerprint(patches: &[Patch]) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h = OFFSET;
    let mut eat = |word: u64| {
        for b in word.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(PRIME);
        }
    };
    let bits = |x: f64| (x + 0.0).to_bits();
    eat(patches.len() as u64);
    for p in patches {
        eat(p.face as u64);
        eat(p.material as u64);
        eat(bits(p.area));
        for v in [p.centroid, p.normal] {
            eat(bits(v.x));
            eat(bits(v.y));
            eat(bits(v.z));
        }
    }
    h
}

/// A sparsified matrix and the energy each row and each receiver lost.
#[derive(Clone, Debug, PartialEq)]
pub struct Sparsified {
    /// The kept entries (values unchanged, never renormalized).
    pub matrix: FormFactorMatrix,
    /// Per row `i`, the sum of the dropped `F_ij`.
    pub dropped: Vec<f64>,
    /// Per receiver `j`, the sum of the dropped `A_i F_ij` (power lost under uniform unit radiosity).
    pub dropped_incoming: Vec<f64>,
    /// Per receiver `j`, `sum_i A_i F_ij` over the original entries (power received under uniform unit
    /// radiosity).
    pub incoming: Vec<f64>,
}

/// Drops entries while both the shooter's and the receiver's budgets allow (see the module docs).
///
/// Entries are visited in ascending order of the power they carry under uniform unit radiosity, `A_i F_ij`
/// (ties by shooter, then receiver); entry `(i, j)` is dropped if afterwards row `i` has lost at most
/// `threshold * s_i` and receiver `j` at most `threshold * sum_k A_k F_kj`. Budgets only fill up, so every kept
/// entry would overflow one of them.
///
/// # Errors
/// [`BakeError::BadThreshold`] if `threshold` is not in `[0, 1)`, [`BakeError::Input`] if `area` does not have
/// one entry per patch.
pub fn sparsify(ff: &FormFactorMatrix, area: &[f64], threshold: f64) -> Result<Sparsified, BakeError> {
    if !(0.0..1.0).contains(&threshold) {
        return Err(BakeError::BadThreshold(threshold));
    }
    let n = ff.n();
    if area.len() != n {
        return Err(input_error(format!("{} areas for {n} patches", area.len())));
    }
    let mut row_of = vec![0usize; ff.nonzeros()];
    let mut incoming = vec![0.0; n];
    for (i, &a) in area.iter().enumerate() {
        for k in ff.row_range(i) {
            row_of[k] = i;
            incoming[ff.columns()[k] as usize] += a * ff.values()[k];
        }
    }
    // Sort keys computed once (the comparison would otherwise fetch two rows' areas per call), then the
    // position: an unstable sort of unique keys gives the stable order.
    let mut order: Vec<(i64, usize)> =
        (0..ff.nonzeros()).map(|k| (total_order_key(area[row_of[k]] * ff.values()[k]), k)).collect();
    order.sort_unstable();
    let row_budget: Vec<f64> = (0..n).map(|i| threshold * ff.row_sum(i)).collect();
    let mut dropped = vec![0.0; n];
    let mut dropped_incoming = vec![0.0; n];
    let mut keep = vec![true; ff.nonzeros()];
    for (_, k) in order {
        let (i, j, f) = (row_of[k], ff.columns()[k] as usize, ff.values()[k]);
        let p = area[i] * f;
        if dropped[i] + f <= row_budget[i] && dropped_incoming[j] + p <= threshold * incoming[j] {
            dropped[i] += f;
            dropped_incoming[j] += p;
            keep[k] = false;
        }
    }
    let matrix = ff.retain_entries(|k| keep[k]);
    Ok(Sparsified { matrix, dropped, dropped_incoming, incoming })
}

/// `f64::total_cmp`'s order as an integer: the sign-magnitude bits turned into two's complement.
fn total_order_key(x: f64) -> i64 {
    let bits = x.to_bits() as i64;
    bits ^ ((((bits >> 63) as u64) >> 1) as i64)
}

/// The shooting form `F~_ij = A_j F_ji / A_i` of shooter rows `ff` with patch areas `area`: the matrix whose
/// gathering solve `B = E + R F~ B` is what shooting with `ff` converges to. Equal to `ff` when `ff` is
/// reciprocal.
///
/// # Panics
/// If `area` is shorter than `ff.n()`, or an area is zero (the shooting form would not be finite).
#[must_use]
pub fn shooting_form(ff: &FormFactorMatrix, area: &[f64]) -> FormFactorMatrix {
    let n = ff.n();
    let mut count = vec![0usize; n + 1];
    for &j in ff.columns() {
        count[j as usize + 1] += 1;
    }
    for k in 0..n {
        count[k + 1] += count[k];
    }
    let row_start = count.clone();
    let mut col = vec![0u32; ff.nonzeros()];
    let mut value = vec![0.0; ff.nonzeros()];
    let mut flags = vec![false; ff.nonzeros()];
    // Rows of `ff` in increasing order fill each transposed row with increasing columns.
    for i in 0..n {
        for ((&j, &f), &flag) in ff.row_columns(i).iter().zip(ff.row_values(i)).zip(ff.row_flags(i)) {
            let j = j as usize;
            let at = count[j];
            col[at] = i as u32;
            value[at] = area[i] * f / area[j];
            flags[at] = flag;
            count[j] += 1;
        }
    }
    FormFactorMatrix::with_flags(n, row_start, col, value, flags)
        .expect("the transpose of a valid matrix is valid (finite values over positive areas)")
}

/// Energy dropped by sparsification (fractions of power; see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EnergyDropped {
    /// Largest per-row dropped sum `d_i`.
    pub max_row: f64,
    /// Mean of `d_i` over rows.
    pub mean_row: f64,
    /// Largest `d_i / s_i` (dropped fraction of a row's energy; `<=` the threshold).
    pub max_row_fraction: f64,
    /// Largest fraction of a receiver's incoming power (under uniform radiosity) dropped (`<=` the threshold).
    pub max_receiver_fraction: f64,
    /// `sum_i d_i`.
    pub total: f64,
    /// `sum_i A_i d_i / sum_i A_i s_i`: fraction of all transported power under uniform radiosity.
    pub area_weighted: f64,
}

/// A dynamic light group as written to the table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroupReport {
    /// Group name.
    pub name: String,
    /// Table id ([`group_id`]).
    pub id: u32,
    /// Member patches.
    pub members: usize,
    /// Default intensity (RGB).
    pub default_intensity: [f64; 3],
}

/// How many patches carry run-time state on the device (see the module docs, step 5).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RuntimeState {
    /// Patches a dynamic light can reach (including the members): the table's state count.
    pub reachable: usize,
    /// Patches in the table.
    pub patches: usize,
    /// Entries dropped from the rows of patches with state because their receiver has none (a receiver black
    /// in every channel: no effect on any radiosity at the baked reflectances).
    pub entries_to_stateless: usize,
}

/// Error of the bake on the scene's own lights (see the module docs, step 6).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeErrors {
    /// Shooting form of the original matrix vs the original (reciprocity of the input).
    pub reciprocity: ErrorReport,
    /// Sparsified matrix (f64) vs the original.
    pub sparsify: ErrorReport,
    /// Everything decoded from the written table vs the original.
    pub sparsify_quantize: ErrorReport,
}

/// The transfer basis of a bake (see [`BakeOptions::transfer`] and the module docs, step 7).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TransferReport {
    /// Bytes of the transfer sections (scale exponents and response codes).
    pub bytes: usize,
    /// Core's f32 transfer relight at the default intensities vs the f64 solve of the original matrix (what
    /// the device shows against the exact answer).
    pub vs_reference: ErrorReport,
    /// The same relight vs f64 `B_static + sum_g I_g T_g` on the table's own (sparsified) matrix: the
    /// quantization of the basis and the static base alone.
    pub quantization: ErrorReport,
}

/// The bake summary.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeReport {
    /// Patches.
    pub patches: usize,
    /// Materials.
    pub materials: usize,
    /// Dynamic light groups.
    pub groups: Vec<GroupReport>,
    /// Light-group members in total.
    pub members: usize,
    /// Sparsification threshold.
    pub threshold: f64,
    /// Nonzero form factors before sparsification.
    pub nonzeros_before: usize,
    /// Nonzero form factors after sparsification.
    pub nonzeros_after: usize,
    /// Entries stored in the table: the sparsified rows of the patches with run-time state, without their
    /// entries to receivers without state (equal to `nonzeros_after` when every patch has state).
    pub table_entries: usize,
    /// Energy dropped by sparsification.
    pub energy_dropped: EnergyDropped,
    /// Codec name (core's `Display` of `FfCodec`).
    pub codec: String,
    /// Bits per form-factor code.
    pub ff_bits: u8,
    /// Table bytes per section.
    pub table_bytes: SectionBytes,
    /// Total table bytes per stored entry.
    pub bytes_per_entry: f64,
    /// Whether the static base is solved (always true for a bake).
    pub base_solved: bool,
    /// Patches with static emission.
    pub static_emitters: usize,
    /// Patches needing run-time state.
    pub runtime_state: RuntimeState,
    /// Error introduced by the bake.
    pub error: BakeErrors,
    /// The scene fingerprint stored in the table ([`scene_fingerprint`]).
    pub fingerprint: u64,
    /// The transfer basis, if baked.
    pub transfer: Option<TransferReport>,
    /// Largest relative residual of the f64 solves.
    pub reference_residual: f64,
}

impl fmt::Display for BakeReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let e = &self.energy_dropped;
        writeln!(f, "patches            {} ({} materials)", self.patches, self.materials)?;
        writeln!(f, "scene fingerprint  {:#018x}", self.fingerprint)?;
        writeln!(f, "light groups       {} dynamic, {} members", self.groups.len(), self.members)?;
        for g in &self.groups {
            writeln!(
                f,
                "  {:<16} id {:#010x}  {} members  default {:?}",
                g.name, g.id, g.members, g.default_intensity
            )?;
        }
        writeln!(f, "static emitters    {} patches (folded into the solved base)", self.static_emitters)?;
        writeln!(
            f,
            "form factors       {} -> {} nonzeros (threshold {}), {} stored (rows of patches with state)",
            self.nonzeros_before, self.nonzeros_after, self.threshold, self.table_entries
        )?;
        writeln!(
            f,
            "energy dropped     per row max {:.3e} mean {:.3e}; max fraction of a row {:.3e}, of a receiver {:.3e}; \
             total {:.3e}, area-weighted {:.3e}",
            e.max_row, e.mean_row, e.max_row_fraction, e.max_receiver_fraction, e.total, e.area_weighted
        )?;
        writeln!(f, "codec              {} ({} bits)", self.codec, self.ff_bits)?;
        writeln!(
            f,
            "table bytes        {} ({:.2} bytes per entry)",
            self.table_bytes.total, self.bytes_per_entry
        )?;
        writeln!(f, "{}", self.table_bytes)?;
        writeln!(
            f,
            "runtime state      {} of {} patches (reachable by a dynamic light; the others show the static \
             base; {} entries to black stateless receivers dropped)",
            self.runtime_state.reachable, self.runtime_state.patches, self.runtime_state.entries_to_stateless
        )?;
        let line = |name: &str, r: &ErrorReport| {
            format!(
                "  {name:<18} rel L2 {:.3e}  max rel {:.3e} (patch {})",
                r.rel_l2, r.max_rel, r.max_rel_patch
            )
        };
        writeln!(f, "error vs f64 (scene lights at default intensity)")?;
        writeln!(f, "{}", line("reciprocity", &self.error.reciprocity))?;
        writeln!(f, "{}", line("sparsify", &self.error.sparsify))?;
        writeln!(f, "{}", line("sparsify+quantize", &self.error.sparsify_quantize))?;
        if let Some(t) = &self.transfer {
            writeln!(
                f,
                "transfer basis     {} bytes ({} groups x {} patches)",
                t.bytes,
                self.groups.len(),
                self.patches
            )?;
            writeln!(f, "{}", line("transfer relight", &t.vs_reference))?;
            writeln!(f, "{}", line("  quantization", &t.quantization))?;
        }
        write!(f, "reference residual {:.3e}", self.reference_residual)
    }
}

/// What a firmware build needs to know of one table: its counts, the solver's buffer sizes (core's
/// [`BufferSizes::of`], the one place they are derived) and the transfer relight's needs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Capacities {
    /// Patches.
    pub patches: usize,
    /// Patches with run-time state (the table's state count; the per-patch buffers' length).
    pub state: usize,
    /// Materials.
    pub materials: usize,
    /// Light groups.
    pub groups: usize,
    /// Light-group members.
    pub members: usize,
    /// Stored form-factor entries.
    pub entries: usize,
    /// Longest row (entries).
    pub max_row_len: usize,
    /// Elements of each solver buffer (and of the Jacobi scratch buffer: `slots`).
    pub buffers: BufferSizes,
    /// Bytes of RAM the solver's buffers take with f32 (`BufferSizes::bytes`).
    pub buffer_bytes_f32: usize,
    /// Bytes of RAM the solver's buffers take with fixed point.
    pub buffer_bytes_fixed: usize,
    /// Output elements (`[S; 3]`) of [`radiosity_core::relight_transfer`]: patches with a transfer basis, else 0.
    pub transfer_out: usize,
    /// Work units of one [`radiosity_core::relight_transfer`] ([`radiosity_core::transfer_cost`]); 0 without a
    /// transfer basis.
    pub transfer_cost: usize,
    /// Table size in bytes.
    pub table_bytes: usize,
}

impl Capacities {
    /// The capacities of a parsed table.
    #[must_use]
    pub fn of_table(table: &Table<'_>, table_bytes: usize) -> Capacities {
        let n = table.patch_count() as usize;
        let max_row_len = (0..table.state_count())
            .filter_map(|i| table.row(i))
            .map(|r| (r.end - r.start) as usize)
            .max()
            .unwrap_or(0);
        let members = (0..table.group_count())
            .filter_map(|g| table.group_members(g))
            .map(|r| (r.end - r.start) as usize)
            .sum();
        let buffers = BufferSizes::of(table);
        Capacities {
            patches: n,
            state: table.state_count() as usize,
            materials: table.material_count() as usize,
            groups: table.group_count() as usize,
            members,
            entries: table.entry_count() as usize,
            max_row_len,
            buffers,
            buffer_bytes_f32: buffers.bytes::<f32>(),
            buffer_bytes_fixed: buffers.bytes::<radiosity_core::Fixed>(),
            transfer_out: if table.has_transfer() { n } else { 0 },
            transfer_cost: if table.has_transfer() {
                radiosity_core::transfer_cost(table) as usize
            } else {
                0
            },
            table_bytes,
        }
    }
}

/// The result of a bake.
#[derive(Clone, Debug)]
pub struct Baked {
    /// The table bytes.
    pub table: Vec<u8>,
    /// The summary.
    pub report: BakeReport,
    /// Buffer sizes for firmware.
    pub capacities: Capacities,
    /// The sparsified f64 matrix (shooter rows) the table was quantized from.
    pub sparse: Sparsified,
    /// Per patch, whether it needs run-time state.
    pub reachable: Vec<bool>,
    /// The f64 static solution `B_s` (W/m^2) on the sparsified matrix.
    pub static_radiosity: Vec<[f64; 3]>,
}

fn input_error(msg: String) -> BakeError {
    BakeError::Input(msg)
}

fn check_input(input: &BakeInput<'_>) -> Result<(), BakeError> {
    let n = input.patches.len();
    let l = input.lighting;
    let lens = [
        ("form-factor matrix", input.form_factors.n()),
        ("lighting.rho", l.rho.len()),
        ("lighting.static_emission", l.static_emission.len()),
        ("lighting.unit_emission", l.unit_emission.len()),
        ("lighting.group", l.group.len()),
    ];
    for (what, len) in lens {
        if len != n {
            return Err(input_error(format!("{what} has {len} entries, expected {n} (one per patch)")));
        }
    }
    let g = l.dynamic_groups.len();
    if l.default_intensity.len() != g || input.group_names.len() != g {
        return Err(input_error(format!(
            "{g} dynamic light groups but {} default intensities and {} names",
            l.default_intensity.len(),
            input.group_names.len()
        )));
    }
    for (k, p) in input.patches.iter().enumerate() {
        let Some(rho) = input.materials.get(p.material) else {
            return Err(input_error(format!("patch {k}: material {} not in the material list", p.material)));
        };
        if *rho != l.rho[k] {
            return Err(input_error(format!(
                "patch {k}: lighting reflectance {:?} differs from its material's {:?}",
                l.rho[k], rho
            )));
        }
        if let Some(grp) = l.group[k] {
            if grp >= g {
                return Err(input_error(format!("patch {k}: dynamic light group {grp} out of range")));
            }
        }
    }
    Ok(())
}

fn to_f32x3(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}

/// Patches needing run-time state (see the module docs, step 5), breadth-first over the stored rows.
#[must_use]
pub fn reachable_patches(sparse: &FormFactorMatrix, group: &[Option<usize>], rho: &[[f64; 3]]) -> Vec<bool> {
    let mut reached = vec![false; sparse.n()];
    let mut queue = VecDeque::new();
    for (i, g) in group.iter().enumerate() {
        if g.is_some() {
            reached[i] = true;
            queue.push_back(i);
        }
    }
    while let Some(i) = queue.pop_front() {
        for (j, f) in sparse.row(i) {
            if f > 0.0 && !reached[j] && rho[j].iter().any(|&r| r > 0.0) {
                reached[j] = true;
                queue.push_back(j);
            }
        }
    }
    reached
}

/// The rows of the patches with run-time state, as core's writer takes them: shooter and receiver indices are
/// slots (positions in `patch`).
struct SlotRows {
    /// Patch of each slot, ascending.
    patch: Vec<u32>,
    row_start: Vec<u32>,
    receiver: Vec<u32>,
    value: Vec<f64>,
    /// Entries of rows with state whose receiver has none (dropped).
    dropped: usize,
}

impl SlotRows {
    fn new(ff: &FormFactorMatrix, state: &[bool]) -> SlotRows {
        let mut slot_of = vec![None; ff.n()];
        let mut patch = Vec::new();
        for (i, _) in state.iter().enumerate().filter(|(_, &s)| s) {
            slot_of[i] = Some(patch.len() as u32);
            patch.push(i as u32);
        }
        let mut rows =
            SlotRows { patch, row_start: vec![0], receiver: Vec::new(), value: Vec::new(), dropped: 0 };
        for &i in &rows.patch {
            for (j, f) in ff.row(i as usize) {
                match slot_of[j] {
                    Some(r) => {
                        rows.receiver.push(r);
                        rows.value.push(f);
                    }
                    None => rows.dropped += 1,
                }
            }
            rows.row_start.push(rows.receiver.len() as u32);
        }
        rows
    }
}

/// Solves `B = E + R F B` for each right-hand side (one factorization for all with the dense method); returns
/// each solution and the largest relative residual.
fn solve_set(
    what: &'static str,
    rho: &[[f64; 3]],
    ff: &FormFactorMatrix,
    rhs: &[&[[f64; 3]]],
    options: &BakeOptions,
) -> Result<(Vec<Radiosity>, f64), BakeError> {
    let wrap = |source| BakeError::Reference { what, source };
    let system = RadiositySystem::with_row_sum_tolerance(rho, ff, options.row_sum_tolerance).map_err(wrap)?;
    let method = options.method.unwrap_or_else(|| default_method(ff.n()));
    let solutions = solve_many(system, rhs, &method).map_err(wrap)?;
    let residual = solutions.iter().flat_map(|s| s.residual).fold(0.0, f64::max);
    Ok((solutions.into_iter().map(|s| s.b).collect(), residual))
}

fn solve_one(
    what: &'static str,
    rho: &[[f64; 3]],
    ff: &FormFactorMatrix,
    e: &[[f64; 3]],
    options: &BakeOptions,
) -> Result<(Radiosity, f64), BakeError> {
    let (mut b, residual) = solve_set(what, rho, ff, &[e], options)?;
    Ok((b.pop().unwrap_or_default(), residual))
}

/// Largest patch count for which a bake solves with dense LU by default.
pub const DENSE_BAKE_LIMIT: usize = 1024;

/// The bake's default reference solver: dense LU up to [`DENSE_BAKE_LIMIT`] patches, Gauss-Seidel above. A
/// bake solves four different matrices (original, its shooting form, sparsified, decoded) with up to three
/// distinct reflectance channels each; at `n` in the thousands that is a dozen `O(n^3)` factorizations, while
/// a sparse Gauss-Seidel sweep costs `O(nonzeros)`.
#[must_use]
pub fn default_method(n: usize) -> Method {
    if n <= DENSE_BAKE_LIMIT {
        Method::Dense { limit: DENSE_BAKE_LIMIT }
    } else {
        Method::GaussSeidel(GaussSeidelOptions::default())
    }
}

/// Everything the device sees, decoded back from a parsed table into f64: reflectance per patch, emission per
/// patch with every group at its default intensity, areas, the shooter rows (patch-indexed; a patch without
/// run-time state has an empty row and receives nothing) and the static base.
///
/// What the device converges to is [`Decoded::solution`] of the f64 solve of `(rho, shooting form of rows,
/// rhs)`: with a solved base the device starts from the static base and shoots only the light groups, so
/// `B = B_base + (I - R F~)^-1 E_dyn`; without one it shoots everything, `B = (I - R F~)^-1 (E_s + E_dyn)`.
#[derive(Clone, Debug)]
pub struct Decoded {
    /// Reflectance per patch (decoded codes).
    pub rho: Vec<[f64; 3]>,
    /// Static plus dynamic emission per patch at the table's default intensities (W/m^2).
    pub emission: Vec<[f64; 3]>,
    /// The right-hand side the device shoots (W/m^2): the dynamic emission with a solved base, else
    /// [`Decoded::emission`].
    pub rhs: Vec<[f64; 3]>,
    /// The static base `E_s + rho G_s` per patch (decoded codes) when the base is solved, else zero.
    pub base: Vec<[f64; 3]>,
    /// Patch areas (the table's f32 values).
    pub area: Vec<f64>,
    /// Shooter rows with decoded form factors, patch-indexed (empty rows for patches without state).
    pub rows: FormFactorMatrix,
    /// Whether each patch has run-time state.
    pub state: Vec<bool>,
}

impl Decoded {
    /// The device's converged answer from `response`, the f64 solve of `rho`, the shooting form of `rows` and
    /// `rhs`: `base + response`.
    #[must_use]
    pub fn solution(&self, mut response: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
        for (b, s) in response.iter_mut().zip(&self.base) {
            for c in 0..3 {
                b[c] += s[c];
            }
        }
        response
    }
}

/// Decodes a parsed table into f64: what the device computes with, for comparison with the f64 reference.
#[must_use]
pub fn decode_table(table: &Table<'_>) -> Decoded {
    use radiosity_core::codec::{decode_emission_f32, decode_reflectance};
    let n = table.patch_count();
    let emission_of = |codes: [u16; 3]| codes.map(|c| f64::from(decode_emission_f32(c)));
    let solved = table.base_solved();
    let mut d = Decoded {
        rho: Vec::with_capacity(n as usize),
        emission: Vec::with_capacity(n as usize),
        rhs: Vec::with_capacity(n as usize),
        base: Vec::with_capacity(n as usize),
        area: Vec::with_capacity(n as usize),
        rows: FormFactorMatrix::default(),
        state: Vec::with_capacity(n as usize),
    };
    let (mut row_start, mut col, mut value) = (vec![0], Vec::new(), Vec::new());
    for i in 0..n {
        let m = table.material(i).unwrap_or(0);
        let r = table.reflectance(m).unwrap_or([0; 3]);
        let rho = r.map(|c| f64::from(decode_reflectance(c).to_f32()));
        let e = emission_of(table.base_emission(i).unwrap_or([0; 3]));
        let g = emission_of(table.base_irradiance(i).unwrap_or([0; 3]));
        d.rho.push(rho);
        d.emission.push(e);
        d.rhs.push(if solved { [0.0; 3] } else { e });
        d.base.push(if solved { [0, 1, 2].map(|c| e[c] + rho[c] * g[c]) } else { [0.0; 3] });
        d.area.push(f64::from(table.area(i).unwrap_or(0.0)));
        let slot = table.slot_of(i);
        d.state.push(slot.is_some());
        if let Some(slot) = slot {
            for k in table.row(slot).unwrap_or(0..0) {
                if let Some((j, f)) = table.entry(slot, k) {
                    col.push(table.slot_patch(j).unwrap_or(0));
                    value.push(f64::from(f.to_f32()));
                }
            }
        }
        row_start.push(col.len());
    }
    // `Table::parse` proved every row's receivers strictly increasing and the slot -> patch map increasing and in
    // range, and decoded codes are finite.
    d.rows = FormFactorMatrix::new(n as usize, row_start, col, value)
        .expect("a parsed table's rows form a valid matrix");
    for g in 0..table.group_count() {
        let intensity = table.default_intensity(g).unwrap_or([0.0; 3]);
        for k in table.group_members(g).unwrap_or(0..0) {
            if let Some(m) = table.member(k) {
                let e = emission_of(m.emission);
                for c in 0..3 {
                    let v = f64::from(intensity[c]) * e[c];
                    d.emission[m.patch as usize][c] += v;
                    d.rhs[m.patch as usize][c] += v;
                }
            }
        }
    }
    d
}

/// Relights `table` with core's f32 transfer relight at `intensity` and compares it with the f64 reference
/// `b_ref` (original matrix) and with the f64 basis `tv` it was quantized from.
fn transfer_report(
    table: &Table<'_>,
    tv: &TransferVectors,
    intensity: &[[f64; 3]],
    b_ref: &[[f64; 3]],
    area: &[f64],
    bytes: &SectionBytes,
) -> Result<TransferReport, BakeError> {
    let i_f32: Vec<[f32; 3]> = intensity.iter().map(|&v| to_f32x3(v)).collect();
    let mut out = vec![[0.0f32; 3]; table.patch_count() as usize];
    radiosity_core::relight_transfer(table, &i_f32, &mut out).map_err(BakeError::Transfer)?;
    let relit: Vec<[f64; 3]> = out.iter().map(|b| b.map(f64::from)).collect();
    // The f64 basis at the intensities the device was given (f32-rounded), so only the basis's quantization
    // and the static base's codes separate the two.
    let i_used: Vec<[f64; 3]> = i_f32.iter().map(|v| v.map(f64::from)).collect();
    let exact =
        tv.relight(&i_used).map_err(|source| BakeError::Reference { what: "transfer relight", source })?;
    Ok(TransferReport {
        bytes: bytes.transfer,
        vs_reference: metrics::compare(&relit, b_ref, area)?,
        quantization: metrics::compare(&relit, &exact, area)?,
    })
}

/// Bakes a table (see the module docs for the steps).
///
/// # Errors
/// A bad threshold, inconsistent input, a group id collision, a failing f64 solve, or a table core's writer
/// rejects (e.g. emission beyond the emission code's range, a row sum above 1).
pub fn bake(input: &BakeInput<'_>, options: &BakeOptions) -> Result<Baked, BakeError> {
    check_input(input)?;
    let n = input.patches.len();
    let lighting = input.lighting;
    let ff = input.form_factors;
    let area: Vec<f64> = input.patches.iter().map(|p| p.area).collect();

    // 1. Sparsify.
    let sparse = sparsify(ff, &area, options.threshold)?;
    let row_sums: Vec<f64> = (0..n).map(|i| ff.row_sum(i)).collect();
    let total_transport: f64 = row_sums.iter().zip(&area).map(|(s, a)| s * a).sum();
    let energy_dropped = EnergyDropped {
        max_row: sparse.dropped.iter().copied().fold(0.0, f64::max),
        mean_row: if n == 0 { 0.0 } else { sparse.dropped.iter().sum::<f64>() / n as f64 },
        max_row_fraction: sparse
            .dropped
            .iter()
            .zip(&row_sums)
            .map(|(&d, &s)| if s > 0.0 { d / s } else { 0.0 })
            .fold(0.0, f64::max),
        max_receiver_fraction: sparse
            .dropped_incoming
            .iter()
            .zip(&sparse.incoming)
            .map(|(&d, &s)| if s > 0.0 { d / s } else { 0.0 })
            .fold(0.0, f64::max),
        total: sparse.dropped.iter().sum(),
        area_weighted: if total_transport > 0.0 {
            sparse.dropped.iter().zip(&area).map(|(d, a)| d * a).sum::<f64>() / total_transport
        } else {
            0.0
        },
    };

    // 2. Static base on the shooting form of the sparsified matrix.
    let sparse_shoot = shooting_form(&sparse.matrix, &area);
    let e = lighting.default_emission();
    let (sparse_solutions, res_sparse) =
        solve_set("sparsified", &lighting.rho, &sparse_shoot, &[&lighting.static_emission, &e], options)?;
    let (b_static, b_sparse) = match <[Radiosity; 2]>::try_from(sparse_solutions) {
        Ok([s, d]) => (s, d),
        Err(_) => {
            return Err(BakeError::Input("reference solver returned the wrong number of solutions".into()))
        }
    };
    let irradiance: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let mut g = [0.0; 3];
            for (j, f) in sparse_shoot.row(i) {
                for c in 0..3 {
                    g[c] += f * b_static[j][c];
                }
            }
            g
        })
        .collect();
    let patch_specs: Vec<PatchSpec> = input
        .patches
        .iter()
        .enumerate()
        .map(|(i, p)| PatchSpec {
            area: p.area as f32,
            material: u32::try_from(p.material).unwrap_or(u32::MAX),
            base_emission: to_f32x3(lighting.static_emission[i]),
            base_irradiance: to_f32x3(irradiance[i]),
        })
        .collect();

    // 3. Dynamic light groups.
    let ids: Vec<u32> = input.group_names.iter().map(|s| group_id(s)).collect();
    for a in 0..ids.len() {
        for b in a + 1..ids.len() {
            if ids[a] == ids[b] {
                let names = (input.group_names[a].clone(), input.group_names[b].clone());
                return Err(BakeError::GroupIdCollision(names.0, names.1, ids[a]));
            }
        }
    }
    let mut members: Vec<Vec<MemberSpec>> = vec![Vec::new(); ids.len()];
    for (i, g) in lighting.group.iter().enumerate() {
        if let Some(g) = *g {
            members[g].push(MemberSpec { patch: i as u32, emission: to_f32x3(lighting.unit_emission[i]) });
        }
    }
    let groups: Vec<GroupSpec<'_>> = ids
        .iter()
        .zip(&members)
        .zip(&lighting.default_intensity)
        .map(|((&id, m), &d)| GroupSpec { id, default_intensity: to_f32x3(d), members: m })
        .collect();

    // 7 (solved before writing). Transfer basis on the table's own matrix, the shooting form of the sparsified
    // rows, so that it and the base describe the same system the device's shooting converges to.
    let transfer = if options.transfer {
        let system =
            RadiositySystem::with_row_sum_tolerance(&lighting.rho, &sparse_shoot, options.row_sum_tolerance)
                .map_err(|source| BakeError::Reference { what: "transfer basis", source })?;
        let lights = LightGroupEmission::of(lighting);
        let method = options.method.unwrap_or_else(|| default_method(n));
        Some(
            transfer_vectors(system, &lights, &method)
                .map_err(|source| BakeError::Reference { what: "transfer basis", source })?,
        )
    } else {
        None
    };
    // Patch-major, as core's writer takes it: response of patch i to group g at [i * groups + g].
    let transfer_residual = transfer.as_ref().map(|tv| tv.residual);
    let transfer_f32: Option<Vec<[f32; 3]>> =
        transfer.as_ref().map(|tv| (0..n).flat_map(|i| tv.t.iter().map(move |t| to_f32x3(t[i]))).collect());

    // 5 (needed by the writer). Reachability: the patches with run-time state, and their rows over slots.
    let reachable = reachable_patches(&sparse.matrix, &lighting.group, &lighting.rho);
    let slots = SlotRows::new(&sparse.matrix, &reachable);

    // 4. Quantize and write.
    let fingerprint = scene_fingerprint(input.patches);
    let materials: Vec<[f32; 3]> = input.materials.iter().map(|&r| to_f32x3(r)).collect();
    let form_factor: Vec<f32> = slots.value.iter().map(|&f| f as f32).collect();
    let spec = TableSpec {
        patches: &patch_specs,
        materials: &materials,
        groups: &groups,
        rows: RowsSpec { row_start: &slots.row_start, receiver: &slots.receiver, form_factor: &form_factor },
        codec: options.codec,
        base_solved: true,
        fingerprint,
        transfer: transfer_f32.as_deref(),
        state: (slots.patch.len() < n).then_some(slots.patch.as_slice()),
    };
    let len = required_len(&spec).map_err(BakeError::Write)?;
    let mut blob = vec![0u8; len];
    let written = write_table(&spec, &mut blob).map_err(BakeError::Write)?;
    blob.truncate(written);
    let table = Table::parse(&blob).map_err(BakeError::Parse)?;

    // 6. Errors on the scene's own lights.
    let (b_ref, r0) = solve_one("original matrix", &lighting.rho, ff, &e, options)?;
    let (b_recip, r1) =
        solve_one("original, shooting form", &lighting.rho, &shooting_form(ff, &area), &e, options)?;
    let dec = decode_table(&table);
    // The decoded rows' shooting form exceeds the original's row sums by the codec's rounding: an entry in the
    // float range is bumped up by at most one code step, at most 2^-M of the entry for M mantissa bits (core's
    // crate docs, "Error bounds"), so its row sums may exceed 1 + tolerance by that factor (2^-5 with 8-bit
    // codes); the stored rows the device shoots stay <= 1. Beyond that allowance, steps of tiny entries (below
    // the float range, where the writer may round up an entry that is at least half a step) scaled by large
    // sender/receiver area ratios are at work: the codec is too coarse for the scene (CodecTooCoarse).
    let mantissa_bits = i32::from(options.codec.bits.saturating_sub(options.codec.exponent_bits));
    let decoded_options = BakeOptions {
        row_sum_tolerance: options.row_sum_tolerance
            + 2f64.powi(-mantissa_bits) * (1.0 + options.row_sum_tolerance),
        ..*options
    };
    let decoded_gather = shooting_form(&dec.rows, &dec.area);
    let (b_dec, r3) = solve_one("decoded table", &dec.rho, &decoded_gather, &dec.rhs, &decoded_options)
        .map_err(|err| match err {
            BakeError::Reference {
                source: ReferenceError::RowSumTooLarge { row, sum, tolerance }, ..
            } => {
                let ratio =
                    decoded_gather.row(row).map(|(j, _)| dec.area[j] / dec.area[row]).fold(0.0, f64::max);
                BakeError::CodecTooCoarse {
                    bits: options.codec.bits,
                    patch: row,
                    area: dec.area[row],
                    sum,
                    tolerance,
                    ratio,
                }
            }
            other => other,
        })?;
    let b_dec = dec.solution(b_dec);
    let error = BakeErrors {
        reciprocity: metrics::compare(&b_recip, &b_ref, &area)?,
        sparsify: metrics::compare(&b_sparse, &b_ref, &area)?,
        sparsify_quantize: metrics::compare(&b_dec, &b_ref, &area)?,
    };

    let table_bytes = SectionBytes::of(&table);
    let transfer = match &transfer {
        Some(tv) => {
            Some(transfer_report(&table, tv, &lighting.default_intensity, &b_ref, &area, &table_bytes)?)
        }
        None => None,
    };
    let nnz = sparse.matrix.nonzeros();
    let report = BakeReport {
        patches: n,
        materials: input.materials.len(),
        groups: input
            .group_names
            .iter()
            .zip(&ids)
            .zip(&members)
            .zip(&lighting.default_intensity)
            .map(|(((name, &id), m), &d)| GroupReport {
                name: name.clone(),
                id,
                members: m.len(),
                default_intensity: d,
            })
            .collect(),
        members: members.iter().map(Vec::len).sum(),
        threshold: options.threshold,
        nonzeros_before: ff.nonzeros(),
        nonzeros_after: nnz,
        table_entries: slots.receiver.len(),
        energy_dropped,
        codec: options.codec.to_string(),
        ff_bits: options.codec.bits,
        bytes_per_entry: if slots.receiver.is_empty() {
            0.0
        } else {
            blob.len() as f64 / slots.receiver.len() as f64
        },
        table_bytes,
        base_solved: true,
        static_emitters: lighting.static_emission.iter().filter(|e| e.iter().any(|&v| v > 0.0)).count(),
        runtime_state: RuntimeState {
            reachable: slots.patch.len(),
            patches: n,
            entries_to_stateless: slots.dropped,
        },
        error,
        reference_residual: [res_sparse, r0, r1, r3].into_iter().chain(transfer_residual).fold(0.0, f64::max),
        fingerprint,
        transfer,
    };
    let capacities = Capacities::of_table(&table, blob.len());
    Ok(Baked { table: blob, report, capacities, sparse, reachable, static_radiosity: b_static })
}

#[cfg(test)]
mod tests {
    use super::total_order_key;

    #[test]
    fn total_order_key_orders_like_total_cmp() {
        let v = [
            f64::NEG_INFINITY,
            -1.0,
            -f64::MIN_POSITIVE,
            -5e-324,
            -0.0,
            0.0,
            5e-324,
            f64::MIN_POSITIVE,
            1.0,
            1.0 + f64::EPSILON,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
            -f64::NAN,
        ];
        for a in v {
            for b in v {
                assert_eq!(total_order_key(a).cmp(&total_order_key(b)), a.total_cmp(&b), "{a:e} vs {b:e}");
            }
        }
    }
}
