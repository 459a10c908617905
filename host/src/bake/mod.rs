//! Baking: turns patches, their lighting and an f64 form-factor matrix into a table the device runs, with a
//! report of what each step did ([`BakeReport`]). A bake only produces: how far the table's answers are from
//! the exact ones is [`crate::evaluate`]'s job (the `bake` command prints both).
//!
//! Steps, in order ([`bake`]):
//!
//! 1. **Sparsify** ([`sparsify`], `sparsify.rs`). Entry `F_ij` of shooter row `i` carries the fraction `F_ij`
//!    of the power leaving patch `i` to receiver `j`; that is the *energy* of an entry, measured by `F` alone,
//!    not `rho_j F_ij` (a black receiver's entries are kept because a run-time reflectance edit may make it
//!    reflect). With threshold `t`, an entry is dropped only if two budgets allow it: its row may lose at most
//!    the fraction `t` of the energy it transports (`d_i <= t s_i`, `s_i` the row sum), and its receiver at most
//!    the fraction `t` of the power it receives under uniform radiosity (`sum_i A_i dF_ij <= t sum_i A_i F_ij`).
//!    The row budget alone is not enough: dropping the same small receiver from many rows (a patch lit only
//!    through weak links, or ties in a uniform row) would leave it dark on the device although no row lost
//!    much. Entries are visited from the least power `A_i F_ij` up. `t = 0` drops nothing (except entries that
//!    are exactly zero, which carry nothing). The dropped energy is reported per row (max, mean, largest
//!    fraction of a row and of a receiver), in total (the sum of all dropped `F_ij`) and area-weighted
//!    (`sum_i A_i d_i / sum_i A_i s_i`, the fraction of all transported power under uniform radiosity)
//!    ([`EnergyDropped`]).
//!
//!    **Dropped energy goes back to the kept entries** ([`DroppedEnergy::ReturnToRow`], the default;
//!    [`Sparsified::return_dropped`]): the kept power exchanges `A_i F_ij` are scaled by a factor per row and
//!    one per receiver (Sinkhorn-Knopp scaling, ending on the rows) until every row sums to its original `s_i`
//!    and every receiver gets its original incoming power `sum_i A_i F_ij`. A row's sum is the energy its
//!    shooter sends, so a closed scene loses nothing to pruning; without this the device's furnace is off by
//!    about `rho d / (1 - rho)`, which `rho = 0.99` makes a hundred times the dropped fraction
//!    (`pruned_quantized_furnace_at_rho_099_stays_within_half_a_percent` in `host/tests/bake/device.rs`). The
//!    receivers' sums are the row sums of the shooting form the device converges to: scaling the rows alone
//!    (each row's kept entries by `s_i / k_i`) was tried first and pushed those up to the threshold above 1 in
//!    closed scenes, past what the reference solve accepts. The scaling needs no geometry and keeps each row's
//!    shape; its cost is that the dropped energy lands on other receivers of the same rows, and that
//!    reciprocity moves by the difference of the factors (each within about the threshold). Both are in the
//!    sparsification error component (the f64 solve of the sparsified rows' shooting form against the full
//!    matrix's, [`crate::evaluate`]); the report prints the largest relative change of a kept entry, of a
//!    receiver's incoming power, and the net loss, measured from the rows ([`EnergyDropped`]).
//!    [`DroppedEnergy::Discard`]
//!    keeps the kept entries unchanged and loses the energy (the bake before issue 19). Both budgets are
//!    independent of the lighting (lights change at run time),
//!    so a dim patch lit mostly through weak links from a bright light can lose more than `t` of its actual
//!    irradiance (`error_grows_with_threshold_and_fewer_bits` in `host/tests/bake/sparsify.rs` prints the
//!    numbers); the evaluation's per-patch maximum shows it.
//! 2. **Static base** (`solve.rs`). Static lights are solved in f64 by the reference solver on the sparsified
//!    matrix and stored as static emission `E_s` and static irradiance `G_s`, with `base_solved = true` (core's
//!    crate docs, "Static base"), so static light costs the device no work.
//!    The device shoots (`H_i += F_ji Phi_j`), so what it converges to solves `B = E + R F~ B` with the
//!    *shooting form* `F~_ij = A_j F_ji / A_i` of the stored rows ([`shooting_form`]). With exact reciprocity
//!    `F~ = F`; after sparsification (or with estimated form factors) they differ slightly, so the base is
//!    solved on `F~` and `G_s_i = sum_j F~_ij B_s_j = (1 / A_i) sum_j F_ji A_j B_s_j` ([`gather`]): this is
//!    exactly a fixed point of the device's shooting, so the base stays converged.
//! 3. **Dynamic light groups** (`ids.rs`) become core's light groups: members are the patches of the group with
//!    their emission at unit intensity, the group's default intensity, and an id [`group_id`] (FNV-1a of the
//!    name).
//! 4. **Transfer basis** (with [`BakeOptions::transfer`]; `solve.rs`). The responses `T_g` of every patch to
//!    every dynamic light group at unit intensity are solved in f64 by [`crate::reference::transfer_vectors`]
//!    on the same shooting form of the sparsified matrix as the static base, to be quantized by core's writer
//!    into the table's transfer section (core's `transfer` module: per group and channel a power-of-two scale,
//!    16-bit small floats). The f64 basis is kept in [`Baked::transfer`].
//! 5. **Reachability** ([`reachable_patches`], `state.rs`). A patch needs run-time state if it is a member of a
//!    dynamic light group, or if its reflectance is nonzero in some channel and it receives a stored entry from
//!    a patch that needs state (a black receiver's radiosity never changes). Only these patches get state in
//!    the table (core's crate docs, "Run-time state"): core's solver sizes its buffers and selection by their
//!    count, and every other patch shows its solved static base. The rows of the patches with state lose their
//!    entries to stateless receivers, which are black in every channel and reflect nothing, so the answer is
//!    unchanged for the baked reflectances; the report counts them ([`RuntimeState`]). Reachability uses the
//!    baked reflectances: a run-time reflectance edit cannot make a black receiver respond to dynamic light.
//!    When every patch is reachable the table gives every patch state and carries no state map.
//! 6. **Quantize and write** with core's codec ([`codec_for_bits`]: 16 -> `FLOAT16`, 8 -> `FLOAT8`),
//!    [`required_len`] and [`write_table`]: the rows of the patches with run-time state only, their receivers
//!    as slots. The table's header carries [`scene_fingerprint`] of the patches, so a tool holding a table and a
//!    scene can tell whether the table was baked from that scene and meshing ([`Table::fingerprint`]).
//! 7. **Codec check** (`codec.rs`). The written table is parsed with [`Table::parse`] and decoded
//!    ([`decode_table`]); the shooting form of the decoded rows must stay a physical system: every patch's
//!    incoming form factors sum to at most `1 +` [`decoded_row_sum_tolerance`], else the codec is too coarse
//!    for the scene ([`BakeError::CodecTooCoarse`]).
//!
//! [`Capacities`] are the sizes a firmware build needs for exactly this table.

mod capacities;
mod codec;
mod decode;
mod hier;
mod ids;
mod report;
mod solve;
mod sparsify;
mod state;

use radiosity_core::{
    required_len, write_table, FfCodec, GroupSpec, MemberSpec, PatchSpec, RowsSpec, Table, TableSpec,
};
use thiserror::Error;

pub use capacities::{patches_within, table_bytes_bound, Capacities, DeviceFit};
pub use codec::{codec_for_bits, decoded_row_sum_tolerance};
pub use decode::{decode_table, Decoded};
pub use hier::{
    bake_hierarchy, BakedHierarchy, ChainCap, HierBakeSummary, HIER_BAKE_TOLERANCE, SUMMARY_FRAME_UNITS,
};
pub use ids::{group_id, group_ids, scene_fingerprint};
pub use report::{BakeReport, GroupReport};
pub(crate) use solve::solve_one;
pub use solve::{default_method, gather, shooting_form, DENSE_BAKE_LIMIT};
pub use sparsify::{sparsify, DroppedEnergy, EnergyDropped, Sparsified, RETURN_ROUNDS, RETURN_TOLERANCE};
pub use state::{reachable_patches, RuntimeState};

use crate::inspect::SectionBytes;
use crate::lighting::PatchLighting;
use crate::patch::{FormFactorMatrix, Patch};
use crate::reference::{Method, ReferenceError, TransferVectors};
use crate::rgb::Rgb;
use crate::scene::Scene;
use state::SlotRows;

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
    /// What becomes of the energy sparsification drops ([`DroppedEnergy`]; by default it goes back to the
    /// kept entries of its row).
    pub dropped_energy: DroppedEnergy,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            threshold: DEFAULT_THRESHOLD,
            codec: FfCodec::FLOAT16,
            row_sum_tolerance: DEFAULT_ROW_SUM_TOLERANCE,
            method: None,
            transfer: false,
            dropped_energy: DroppedEnergy::default(),
        }
    }
}

/// What a bake needs: patches, their lighting, material reflectances, dynamic group names and form factors.
#[derive(Clone, Debug)]
pub struct BakeInput<'a> {
    /// Patches (area and material are used).
    pub patches: &'a [Patch],
    /// Reflectance per material (RGB, each in `[0, 1)`); `Patch::material` indexes it.
    pub materials: Vec<Rgb>,
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
         senders up to {ratio:.0} times its area multiply each code step by that ratio. {}",
        codec_hint(.bits)
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
}

/// The result of a bake.
#[derive(Clone, Debug)]
pub struct Baked {
    /// The table bytes.
    pub table: Vec<u8>,
    /// What each step did.
    pub report: BakeReport,
    /// Buffer sizes for firmware.
    pub capacities: Capacities,
    /// The sparsified f64 matrix (shooter rows) the table was quantized from.
    pub sparse: Sparsified,
    /// Per patch, whether it needs run-time state.
    pub reachable: Vec<bool>,
    /// The f64 static solution `B_s` (W/m^2) on the sparsified matrix.
    pub static_radiosity: Vec<Rgb>,
    /// The f64 transfer basis the table's transfer section was quantized from (with
    /// [`BakeOptions::transfer`]).
    pub transfer: Option<TransferVectors>,
    /// Largest relative residual of the bake's own f64 solves (static base, transfer basis).
    pub residual: f64,
}

/// Bakes a table (see the module docs for the steps).
///
/// # Errors
/// A bad threshold, inconsistent input, a group id collision, a failing f64 solve, a table core's writer
/// rejects (e.g. emission beyond the emission code's range, a row sum above 1), or a codec too coarse for the
/// scene.
pub fn bake(input: &BakeInput<'_>, options: &BakeOptions) -> Result<Baked, BakeError> {
    check_input(input)?;
    let n = input.patches.len();
    let lighting = input.lighting;
    let ff = input.form_factors;
    let area: Vec<f64> = input.patches.iter().map(|p| p.area).collect();
    let method = options.method.unwrap_or_else(|| default_method(n));
    let reference = |what| move |source| BakeError::Reference { what, source };

    // 1. Sparsify.
    let mut sparse = sparsify(ff, &area, options.threshold)?;
    if options.dropped_energy == DroppedEnergy::ReturnToRow {
        sparse.return_dropped(&area);
    }
    let energy_dropped = EnergyDropped::of(ff, &area, &sparse);

    // 2. Static base on the shooting form of the sparsified matrix.
    let sparse_shoot = shooting_form(&sparse.matrix, &area);
    let (b_static, base_residual) = solve_one(
        &lighting.rho,
        &sparse_shoot,
        &lighting.static_emission,
        options.row_sum_tolerance,
        &method,
    )
    .map_err(reference("sparsified"))?;
    let irradiance = gather(&sparse_shoot, &b_static);
    let patch_specs: Vec<PatchSpec> = input
        .patches
        .iter()
        .enumerate()
        .map(|(i, p)| PatchSpec {
            area: p.area as f32,
            material: u32::try_from(p.material).unwrap_or(u32::MAX),
            base_emission: lighting.static_emission[i].as_vec3().to_array(),
            base_irradiance: irradiance[i].as_vec3().to_array(),
        })
        .collect();

    // 3. Dynamic light groups.
    let ids = group_ids(&input.group_names)?;
    let mut members: Vec<Vec<MemberSpec>> = vec![Vec::new(); ids.len()];
    for (i, g) in lighting.group.iter().enumerate() {
        if let Some(g) = *g {
            members[g].push(MemberSpec {
                patch: i as u32,
                emission: lighting.unit_emission[i].as_vec3().to_array(),
            });
        }
    }
    let groups: Vec<GroupSpec<'_>> = ids
        .iter()
        .zip(&members)
        .zip(&lighting.default_intensity)
        .map(|((&id, m), &d)| GroupSpec { id, default_intensity: d.as_vec3().to_array(), members: m })
        .collect();

    // 4. Transfer basis on the table's own matrix, the shooting form of the sparsified rows, so that it and the
    // base describe the same system the device's shooting converges to.
    let transfer = if options.transfer {
        Some(
            solve::transfer_basis(lighting, &sparse_shoot, options.row_sum_tolerance, &method)
                .map_err(reference("transfer basis"))?,
        )
    } else {
        None
    };
    // Patch-major, as core's writer takes it: response of patch i to group g at [i * groups + g].
    let transfer_f32: Option<Vec<[f32; 3]>> = transfer
        .as_ref()
        .map(|tv| (0..n).flat_map(|i| tv.t.iter().map(move |t| t[i].as_vec3().to_array())).collect());

    // 5. Reachability: the patches with run-time state, and their rows over slots.
    let reachable = reachable_patches(&sparse.matrix, &lighting.group, &lighting.rho);
    let slots = SlotRows::new(&sparse.matrix, &reachable);

    // 6. Quantize and write.
    let fingerprint = scene_fingerprint(input.patches);
    let materials: Vec<[f32; 3]> = input.materials.iter().map(|&r| r.as_vec3().to_array()).collect();
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

    // 7. Codec check on the decoded table.
    let table = Table::parse(&blob).map_err(BakeError::Parse)?;
    codec::check_codec(
        &decode_table(&table),
        options.codec,
        decoded_row_sum_tolerance(options.codec, options.row_sum_tolerance),
    )?;

    let table_bytes = SectionBytes::of(&table);
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
        nonzeros_after: sparse.matrix.nonzeros(),
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
        static_emitters: lighting.static_emission.iter().filter(|e| e.cmpgt(Rgb::ZERO).any()).count(),
        runtime_state: slots.runtime_state(n),
        fingerprint,
    };
    let capacities = Capacities::of_table(&table, blob.len());
    let residual = transfer.as_ref().map_or(base_residual, |tv| base_residual.max(tv.residual));
    Ok(Baked {
        table: blob,
        report,
        capacities,
        sparse,
        reachable,
        static_radiosity: b_static,
        transfer,
        residual,
    })
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
                l.rho[k].to_array(),
                rho.to_array()
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

/// What to do about [`BakeError::CodecTooCoarse`] at `bits` per code.
fn codec_hint(bits: &u8) -> &'static str {
    if *bits < 16 {
        "Use --bits 16, or mesh so that small patches do not border much larger ones"
    } else {
        "16 bits is the finest code: mesh so that small patches do not border much larger ones (a smaller \
         --max-patch-edge), or bake the hierarchical table (--method hierarchical)"
    }
}
