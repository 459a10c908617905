//! Synthetic test tables, written with core's writers, for the firmware while no baked scene is available:
//! the flat [`uniform_enclosure`] and the hierarchical [`hierarchical_enclosure`].
//!
//! The **uniform enclosure**: `n` patches of equal area `A` forming a closed enclosure in which every patch sees
//! every other patch equally, `F_ij = 1 / (n - 1)` for `i != j`, `F_ii = 0`. Rows sum to exactly 1 (closed)
//! and reciprocity `A_i F_ij = A_j F_ji` holds because the areas are equal. It is not a geometric scene; it is
//! the densest table a patch count allows (every row has `n - 1` entries), so it is a worst case for the work
//! per shot, and its answer is analytic: with emission `E` on the light patches and reflectance `rho_i`, the
//! radiosity equation `B_i = E_i + rho_i / (n - 1) * sum_{j != i} B_j` is a small linear system.
//!
//! Layout of [`uniform_enclosure`]: 6 "walls" of `k x k` patches (so `n = 6 k^2`): wall 0 (patches
//! `0..k^2`) is red, wall 1 green, the rest white (the Cornell box's published reflectances, rounded); the
//! first `LIGHT_PATCHES` patches of wall 5 form the one light group, at unit intensity emitting the Cornell
//! light's `Ke` (17, 11.8, 4 W/m^2), so the Cornell box's relight scripts (one light group) run on it unchanged.

use radiosity_core::{
    hier_required_len, required_len, write_hier_table, write_table, FfCodec, GroupSpec, HierSpec, MemberSpec,
    NodeSpec, PatchSpec, RowsSpec, TableSpec, WriteError,
};

/// Patches in the light group of [`uniform_enclosure`].
pub const LIGHT_PATCHES: u32 = 4;

/// Name of [`uniform_enclosure`]'s light group: the Cornell box's, so the box's relight scripts, which name
/// the group, run on this table too.
pub const LIGHT_NAME: &str = "light";

/// Light-group id of [`uniform_enclosure`]'s light: [`radiosity_core::group_id`] of [`LIGHT_NAME`], as a bake
/// writes it.
pub const LIGHT_ID: u32 = radiosity_core::group_id(LIGHT_NAME);

/// Reflectances (RGB): white, red, green.
pub const MATERIALS: [[f32; 3]; 3] = [[0.73, 0.73, 0.73], [0.63, 0.06, 0.05], [0.12, 0.45, 0.09]];

/// Unit-intensity emission of the light (W/m^2, RGB), the Cornell box light's `Ke`.
pub const LIGHT_EMISSION: [f32; 3] = [17.0, 11.8, 4.0];

/// Writes the uniform enclosure with `k x k` patches per wall (`n = 6 k^2`, `k >= 1`), each of area `area`,
/// quantized with `codec`.
///
/// # Errors
/// A [`WriteError`] from core's writer (e.g. a bad area).
pub fn uniform_enclosure(k: u32, area: f32, codec: FfCodec) -> Result<Vec<u8>, WriteError> {
    let per_wall = k * k;
    let n = 6 * per_wall;
    let patches: Vec<PatchSpec> = (0..n)
        .map(|i| PatchSpec {
            area,
            material: match i / per_wall {
                0 => 1,
                1 => 2,
                _ => 0,
            },
            base_emission: [0.0; 3],
            base_irradiance: [0.0; 3],
        })
        .collect();
    let members: Vec<MemberSpec> = (0..LIGHT_PATCHES.min(per_wall))
        .map(|m| MemberSpec { patch: 5 * per_wall + m, emission: LIGHT_EMISSION })
        .collect();
    let groups = [GroupSpec { id: LIGHT_ID, default_intensity: [1.0; 3], members: &members }];
    let f = if n > 1 { 1.0 / (n - 1) as f32 } else { 0.0 };
    let mut row_start = vec![0u32];
    let mut receiver = Vec::new();
    for j in 0..n {
        receiver.extend((0..n).filter(|&i| i != j));
        row_start.push(receiver.len() as u32);
    }
    let form_factor = vec![f; receiver.len()];
    let spec = TableSpec {
        patches: &patches,
        materials: &MATERIALS,
        groups: &groups,
        rows: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
        codec,
        base_solved: false,
        fingerprint: 0,
        transfer: None,
        state: None,
    };
    let mut blob = vec![0u8; required_len(&spec)?];
    let len = write_table(&spec, &mut blob)?;
    blob.truncate(len);
    Ok(blob)
}

/// The committed test table `firmware-sim/tables/uniform-enclosure.rft`: `k = 4` (96 patches, 9120 entries),
/// patches of 0.01 m^2 (10 x 10 cm), [`FfCodec::FLOAT16`].
///
/// # Errors
/// As [`uniform_enclosure`].
pub fn default_table() -> Result<Vec<u8>, WriteError> {
    uniform_enclosure(4, 0.01, FfCodec::FLOAT16)
}

/// Nodes per face of [`hierarchical_enclosure`], in preorder: the face, its first half, that half's two
/// leaves, its second half, that half's two leaves.
pub const HIER_NODES_PER_FACE: u32 = 7;

/// Node offsets (within a face's [`HIER_NODES_PER_FACE`]) of the face's two halves.
pub const HIER_HALVES: [u32; 2] = [1, 4];

/// Node offsets (within a face) of the face's four leaves, in leaf order.
pub const HIER_LEAVES: [u32; 4] = [2, 3, 5, 6];

/// Leaves in the light group of [`hierarchical_enclosure`]: the two leaves of face 5's first half.
pub const HIER_LIGHT_LEAVES: [u32; 2] = [20, 21];

/// The faces that face `f` of [`hierarchical_enclosure`] sees: every face but itself and its opposite
/// (`f ^ 1`), in increasing order.
#[must_use]
pub fn adjacent_faces(f: u32) -> [u32; 4] {
    let mut out = [0u32; 4];
    let mut k = 0;
    for g in 0..6 {
        if g != f && g != f ^ 1 {
            out[k] = g;
            k += 1;
        }
    }
    out
}

/// The links of [`hierarchical_enclosure`] as `(sender node, receiver node, form factor)`, grouped by sender
/// in node order, receivers increasing within a sender.
#[must_use]
pub fn hierarchical_links() -> Vec<(u32, u32, f32)> {
    let node = |face: u32, offset: u32| HIER_NODES_PER_FACE * face + offset;
    let mut links = Vec::new();
    for f in 0..6 {
        let adj = adjacent_faces(f);
        // Face level: the whole face to the faces of its first two neighbours.
        links.extend(adj[..2].iter().map(|&g| (node(f, 0), node(g, 0), 0.2)));
        // Half level: each half to both halves of its last two neighbours.
        for h in HIER_HALVES {
            for &g in &adj[2..] {
                links.extend(HIER_HALVES.iter().map(|&r| (node(f, h), node(g, r), 0.1)));
            }
        }
        // Leaf level: each leaf to every leaf of the opposite face.
        for l in HIER_LEAVES {
            links.extend(HIER_LEAVES.iter().map(|&r| (node(f, l), node(f ^ 1, r), 0.05)));
        }
    }
    links.sort_by_key(|&(s, r, _)| (s, r));
    links
}

/// The **hierarchical enclosure**, a hierarchical (version 4) test table: 6 faces of area `4 leaf_area`,
/// each a tree of 7 nodes (face, two halves, two leaves per half: 42 nodes, 24 leaves), every face sending
/// its power equally to the 5 others (`1/5` each), as in [`uniform_enclosure`] with one patch per face, but
/// through links at three levels ([`hierarchical_links`]): a face shoots to the faces of its first two
/// neighbours ([`adjacent_faces`]) as a whole (`F = 1/5`), each half shoots to the halves of its last two
/// neighbours (`1/10` to each half), and each leaf to the leaves of the opposite face (`1/20` each). Every
/// leaf's chain sums to 1: a closed enclosure. Face 0 is red, face 1 green, the rest white ([`MATERIALS`]);
/// [`HIER_LIGHT_LEAVES`] form the one light group, [`LIGHT_NAME`], emitting [`LIGHT_EMISSION`] at unit
/// intensity, so the Cornell box's relight scripts run on it unchanged.
///
/// # Errors
/// A [`WriteError`] from core's writer (e.g. a bad area).
pub fn hierarchical_enclosure(leaf_area: f32, codec: FfCodec) -> Result<Vec<u8>, WriteError> {
    let nodes: Vec<NodeSpec> = (0..6 * HIER_NODES_PER_FACE)
        .map(|n| {
            let (face, offset) = (n / HIER_NODES_PER_FACE, n % HIER_NODES_PER_FACE);
            let base = HIER_NODES_PER_FACE * face;
            let parent = match offset {
                0 => None,
                1 | 4 => Some(base),
                _ if offset < 4 => Some(base + 1),
                _ => Some(base + 4),
            };
            NodeSpec { parent }
        })
        .collect();
    let leaves: Vec<PatchSpec> = (0..24u32)
        .map(|l| PatchSpec {
            area: leaf_area,
            material: match l / 4 {
                0 => 1,
                1 => 2,
                _ => 0,
            },
            base_emission: [0.0; 3],
            base_irradiance: [0.0; 3],
        })
        .collect();
    let members = HIER_LIGHT_LEAVES.map(|patch| MemberSpec { patch, emission: LIGHT_EMISSION });
    let groups = [GroupSpec { id: LIGHT_ID, default_intensity: [1.0; 3], members: &members }];
    let links = hierarchical_links();
    let mut row_start = vec![0u32; nodes.len() + 1];
    for &(s, _, _) in &links {
        row_start[s as usize + 1] += 1;
    }
    for k in 1..row_start.len() {
        row_start[k] += row_start[k - 1];
    }
    let receiver: Vec<u32> = links.iter().map(|l| l.1).collect();
    let form_factor: Vec<f32> = links.iter().map(|l| l.2).collect();
    let spec = HierSpec {
        nodes: &nodes,
        leaves: &leaves,
        materials: &MATERIALS,
        groups: &groups,
        links: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
        codec,
        base_solved: false,
        fingerprint: 0,
        transfer: None,
    };
    let mut blob = vec![0u8; hier_required_len(&spec)?];
    let len = write_hier_table(&spec, &mut blob)?;
    blob.truncate(len);
    Ok(blob)
}

/// The committed hierarchical test table `firmware-sim/tables/hierarchical-enclosure.rft`: leaves of
/// 0.25 m^2 (faces of 1 m^2), [`FfCodec::FLOAT16`].
///
/// # Errors
/// As [`hierarchical_enclosure`].
pub fn default_hierarchical_table() -> Result<Vec<u8>, WriteError> {
    hierarchical_enclosure(0.25, FfCodec::FLOAT16)
}
