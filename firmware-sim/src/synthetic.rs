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
//!
//! Both tables carry a transfer basis (the f64 answer at unit intensity, `unit_response`; no static light,
//! so the static base is zero), so the firmware also measures the transfer relight on them.

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
    uniform_enclosure_lights(k, area, codec, 1)
}

/// Name of light group `g` of [`uniform_enclosure_lights`] with more than one group: `light-<g>`.
#[must_use]
pub fn light_name(g: u32) -> String {
    format!("light-{g}")
}

/// [`uniform_enclosure`] with `groups` light groups: with one, the group [`LIGHT_NAME`] of the first
/// [`LIGHT_PATCHES`] patches of wall 5 (the uniform enclosure itself); with more, group `g` is patch
/// `5 k^2 + g` alone, named [`light_name`]`(g)`, each emitting [`LIGHT_EMISSION`] at unit intensity
/// (`1 <= groups <= k^2`).
///
/// # Errors
/// A [`WriteError`] from core's writer (e.g. a bad area, or more groups than wall 5 has patches).
pub fn uniform_enclosure_lights(
    k: u32,
    area: f32,
    codec: FfCodec,
    groups: u32,
) -> Result<Vec<u8>, WriteError> {
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
    // Members of each group, and each group's id.
    let lit: Vec<(u32, Vec<MemberSpec>)> = if groups == 1 {
        let m = (0..LIGHT_PATCHES.min(per_wall))
            .map(|m| MemberSpec { patch: 5 * per_wall + m, emission: LIGHT_EMISSION });
        vec![(LIGHT_ID, m.collect())]
    } else {
        (0..groups)
            .map(|g| {
                let member = MemberSpec { patch: 5 * per_wall + g, emission: LIGHT_EMISSION };
                (radiosity_core::group_id(&light_name(g)), vec![member])
            })
            .collect()
    };
    let group_specs: Vec<GroupSpec<'_>> =
        lit.iter().map(|(id, members)| GroupSpec { id: *id, default_intensity: [1.0; 3], members }).collect();
    let f = if n > 1 { 1.0 / (n - 1) as f32 } else { 0.0 };
    let mut row_start = vec![0u32];
    let mut receiver = Vec::new();
    for j in 0..n {
        receiver.extend((0..n).filter(|&i| i != j));
        row_start.push(receiver.len() as u32);
    }
    let form_factor = vec![f; receiver.len()];
    // The transfer basis: the f64 answer of `B_i = E_i + rho_i f sum_{j != i} B_j` at unit intensity (no static
    // light, so the static base is zero and solved).
    let rho: Vec<[f64; 3]> = patches.iter().map(|p| MATERIALS[p.material as usize].map(f64::from)).collect();
    let responses: Vec<Vec<[f32; 3]>> = lit
        .iter()
        .map(|(_, members)| {
            let emission: Vec<[f64; 3]> = (0..n)
                .map(|i| {
                    let on = members.iter().any(|m| m.patch == i);
                    if on {
                        LIGHT_EMISSION.map(f64::from)
                    } else {
                        [0.0; 3]
                    }
                })
                .collect();
            unit_response(&emission, &rho, |b| {
                let total = b.iter().fold([0.0; 3], |t, x| [t[0] + x[0], t[1] + x[1], t[2] + x[2]]);
                b.iter().map(|x| [0, 1, 2].map(|c| f64::from(f) * (total[c] - x[c]))).collect()
            })
        })
        .collect();
    // Element-major: every group's response of patch 0, then of patch 1, ...
    let transfer: Vec<[f32; 3]> = (0..n as usize).flat_map(|i| responses.iter().map(move |r| r[i])).collect();
    let spec = TableSpec {
        patches: &patches,
        materials: &MATERIALS,
        groups: &group_specs,
        rows: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
        codec,
        base_solved: true,
        fingerprint: 0,
        transfer: Some(&transfer),
        state: None,
    };
    let mut blob = vec![0u8; required_len(&spec)?];
    let len = write_table(&spec, &mut blob)?;
    blob.truncate(len);
    Ok(blob)
}

/// The response `T` of every element to the one light group at unit intensity, for the transfer basis: the
/// solution of `T = E + rho * gather(T)` (per channel) by Jacobi iteration in f64, `gather` the irradiance each
/// element receives from radiosities `T`. Both enclosures are closed with reflectances at most 0.73, so the
/// iteration contracts by 0.73 per step: 200 steps leave an error below `1e-27` of the emission.
fn unit_response(
    emission: &[[f64; 3]],
    rho: &[[f64; 3]],
    gather: impl Fn(&[[f64; 3]]) -> Vec<[f64; 3]>,
) -> Vec<[f32; 3]> {
    let mut b = emission.to_vec();
    for _ in 0..200 {
        let g = gather(&b);
        b = (0..b.len()).map(|i| [0, 1, 2].map(|c| emission[i][c] + rho[i][c] * g[i][c])).collect();
    }
    b.iter().map(|x| x.map(|v| v as f32)).collect()
}

/// Light groups of [`four_lights_table`].
pub const FOUR_LIGHTS: u32 = 4;

/// The committed test table `firmware-sim/tables/four-lights.rft`: [`default_table`]'s enclosure with
/// [`FOUR_LIGHTS`] light groups of one patch each ([`uniform_enclosure_lights`]), for the transfer relight's
/// cost per element and light group (against the one-group table) and the device loop with several groups;
/// its scripts are `firmware-sim/tables/four-lights.relight.toml`.
///
/// # Errors
/// As [`uniform_enclosure_lights`].
pub fn four_lights_table() -> Result<Vec<u8>, WriteError> {
    uniform_enclosure_lights(4, 0.01, FfCodec::FLOAT16, FOUR_LIGHTS)
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

/// The **hierarchical enclosure**, a hierarchical (version 5) test table: 6 faces of area `4 leaf_area`,
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
    // The transfer basis: the f64 answer of the links' system at unit intensity. Every node of a face level
    // has the same area as the nodes it links to, so a link's irradiance at its receiver is `F` times the
    // sender's mean radiosity; a leaf gathers through its own node and its two ancestors.
    let emission: Vec<[f64; 3]> = (0..24u32)
        .map(|l| if HIER_LIGHT_LEAVES.contains(&l) { LIGHT_EMISSION.map(f64::from) } else { [0.0; 3] })
        .collect();
    let rho: Vec<[f64; 3]> = leaves.iter().map(|p| MATERIALS[p.material as usize].map(f64::from)).collect();
    let leaf_of = |n: u32| {
        let offset = n % HIER_NODES_PER_FACE;
        HIER_LEAVES.iter().position(|&o| o == offset).map(|k| 4 * (n / HIER_NODES_PER_FACE) + k as u32)
    };
    // The leaves below node `n`.
    let below = |n: u32| -> Vec<u32> {
        let face = n / HIER_NODES_PER_FACE;
        match n % HIER_NODES_PER_FACE {
            0 => (4 * face..4 * face + 4).collect(),
            1 => vec![4 * face, 4 * face + 1],
            4 => vec![4 * face + 2, 4 * face + 3],
            _ => leaf_of(n).into_iter().collect(),
        }
    };
    let transfer = unit_response(&emission, &rho, |b| {
        let mut gathered = vec![[0.0f64; 3]; b.len()];
        for &(s, r, f) in &links {
            let from = below(s);
            let mean =
                [0, 1, 2].map(|c| from.iter().map(|&l| b[l as usize][c]).sum::<f64>() / from.len() as f64);
            for l in below(r) {
                for c in 0..3 {
                    gathered[l as usize][c] += f64::from(f) * mean[c];
                }
            }
        }
        gathered
    });
    let spec = HierSpec {
        nodes: &nodes,
        leaves: &leaves,
        materials: &MATERIALS,
        groups: &groups,
        links: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
        codec,
        base_solved: true,
        fingerprint: 0,
        transfer: Some(&transfer),
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
