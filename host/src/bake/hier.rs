//! Baking a hierarchical device table (core's format version 5) from a hierarchical solution: the solve's tree
//! and links ([`LinkNetwork`]) become the table's nodes and sender runs, the leaves carry their materials and the
//! static base, and the dynamic light groups' members are leaves.
//!
//! # Chain sums
//! A leaf's power leaves through the runs of its whole chain (its own and its ancestors'), each at the node's
//! average share, so a leaf that sees less than its ancestors' average (one in a corner) may send on more than
//! it holds: the sum of its chain's runs exceeds 1, although over an ancestor's leaves the shares average to at
//! most 1. Core accepts a table only if every chain sums to at most 1 (so that shooting converges whatever the
//! reflectances are set to). The bake takes such a leaf's excess off its own run (scaled down; where its own run
//! is too small, every run above it is scaled by the worst leaf below), and reports how many leaves and how much
//! power that touched ([`BakedHierarchy::capped`]).
//!
//! # The table's own answer
//! The device converges to the answer of the table's system (after that cap), which the bake solves in f64 on
//! the sender runs: [`BakedHierarchy::radiosity`] (every light group at its default intensity) and the static
//! radiosity, whose gathered light is the static base `G_s`, so that static light costs the device no work.
//!
//! # Closed scenes
//! In a closed scene every leaf's row sum (what its chain gathers from a uniform radiosity of 1) should be 1, but
//! the hierarchy's averaged links leave it above or below, and with reflectances near 1 that error is multiplied
//! by `1 / (1 - rho)` (the white furnace at rho 0.99 came out far off with the open scenes' cap alone). The
//! hierarchical solve divides what each leaf gathers by its row sum (`hierarchy`, "Closed scenes"); a table cannot
//! carry that factor without a per-leaf product in core's link loop. Instead the bake closes the rows with the
//! links themselves (`Runs::closed`): links are reciprocal (`A_a f_ab = A_b f_ba`), so each leaf's chain of run
//! sums (what it sends on) equals its row sum (what it gathers); a leaf over 1 has its own links scaled down, both
//! directions at once (what remains, every link scaled by the worst row below its ends), which keeps them
//! reciprocal; then each leaf below 1 gets a link to itself carrying the rest. Every chain then sums to 1: core's
//! bound holds, no power is kept back (a closed scene loses none), and a uniform radiosity gathers exactly itself,
//! so the furnace's `E / (1 - rho)` is the table's answer. Elsewhere the two closures differ where a leaf's own
//! radiosity is not the average of what it sees (the self-link assumes the one, the solve's scaling the other);
//! the summary reports how far the table's answer is from the solve's ([`HierBakeSummary::cap_difference`]).

use radiosity_core::{
    hier_required_len, write_hier_table, FfCodec, GroupSpec, HierSpec, HierTable, MemberSpec, NodeSpec,
    PatchSpec, RowsSpec,
};

use super::codec::codec_for_bits;
use super::ids::{group_ids, scene_fingerprint};
use super::BakeError;
use crate::hierarchy::{HierarchicalSolution, LinkNetwork, NetworkLink};
use crate::lighting::PatchLighting;
use crate::rgb::{max_channel, Rgb};
use crate::scene::Scene;

/// Relative change per sweep at which the f64 solve of the table's system stops.
pub const HIER_BAKE_TOLERANCE: f64 = 1e-13;

/// Most sweeps of that solve.
const MAX_SWEEPS: usize = 100_000;

/// What the chain-sum cap changed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChainCap {
    /// Leaves whose chain summed to more than 1.
    pub leaves: usize,
    /// The largest chain sum before the cap.
    pub largest: f64,
    /// The power the cap keeps from being sent on, at the default intensities, as a share of all the leaves'
    /// power.
    pub power_share: f64,
    /// In a closed scene (module docs, "Closed scenes"): the leaves given a self-link to close their row.
    pub self_links: usize,
    /// The largest self-link's form factor.
    pub largest_self_link: f64,
}

/// A hierarchical table and what it was made from.
#[derive(Clone, Debug)]
pub struct BakedHierarchy {
    /// The table bytes.
    pub table: Vec<u8>,
    /// For each table leaf (in node order), its index in the solution's leaves.
    pub solution_leaf: Vec<usize>,
    /// The f64 answer of the table's system (before quantization) with every light group at its default
    /// intensity, per table leaf (W/m^2): what the device converges to but for its codes and arithmetic.
    pub radiosity: Vec<Rgb>,
    /// The f64 static radiosity of the table's system per table leaf (W/m^2).
    pub static_radiosity: Vec<Rgb>,
    /// The f64 response of the table's system to each dynamic light group at unit intensity (white), per table
    /// leaf (W/m^2): with [`BakedHierarchy::static_radiosity`], the answer for any intensities
    /// ([`BakedHierarchy::exact`]).
    pub responses: Vec<Vec<Rgb>>,
    /// Nodes, leaves, links (each link is an entry in both ends' runs).
    pub counts: (usize, usize, usize),
    /// What the chain-sum cap changed.
    pub capped: ChainCap,
    /// Largest chain sum after the cap (at most 1), the table system's `rho_max` times which is its contraction.
    pub chain_sum: f64,
}

impl BakedHierarchy {
    /// The f64 answer of the table's decoded codes (form factors, reflectances, static base; areas and
    /// emissions as the table's f32) with every light group at its default intensity, per table leaf: what the
    /// device converges to but for its arithmetic. Against [`BakedHierarchy::radiosity`], the quantization
    /// component. `network` is the one the table was baked from (`HierarchicalSolution::network`).
    ///
    /// # Errors
    /// [`BakeError::Parse`] if the table does not parse, [`BakeError::Input`] if its nodes are not `network`'s
    /// or the decoded system does not converge.
    pub fn decoded_radiosity(&self, network: &LinkNetwork) -> Result<Vec<Rgb>, BakeError> {
        let table = HierTable::parse(&self.table).map_err(BakeError::Parse)?;
        let b = DecodedHierarchy::new(network, &table)?.answer()?;
        Ok((0..table.leaf_count()).map(|t| table.leaf_node(t).map_or(Rgb::ZERO, |k| b[k as usize])).collect())
    }

    /// The f64 answer of the table's system for light-group `intensity` (RGB per group, table order), per table
    /// leaf: static radiosity plus each group's response times its intensity.
    ///
    /// # Errors
    /// [`BakeError::Input`] if `intensity` does not have one entry per group.
    pub fn exact(&self, intensity: &[Rgb]) -> Result<Vec<Rgb>, BakeError> {
        if intensity.len() != self.responses.len() {
            return Err(BakeError::Input(format!(
                "{} intensities for {} light groups",
                intensity.len(),
                self.responses.len()
            )));
        }
        let mut b = self.static_radiosity.clone();
        for (response, i) in self.responses.iter().zip(intensity) {
            for (b, r) in b.iter_mut().zip(response) {
                *b += *i * *r;
            }
        }
        Ok(b)
    }
}

/// Per node, the largest of `sums` over the leaves below it (itself, for a leaf), and at least 1: the factor
/// that brings every leaf's sum below the node within 1 (the chain cap's and the closed rows' last stage).
fn worst_below(net: &LinkNetwork, sums: &[f64]) -> Vec<f64> {
    let nodes = &net.nodes;
    let mut worst = vec![1.0f64; nodes.len()];
    for k in (0..nodes.len()).rev() {
        if nodes[k].leaf.is_some() {
            worst[k] = worst[k].max(sums[k]);
        }
        if let Some(p) = nodes[k].parent {
            worst[p as usize] = worst[p as usize].max(worst[k]);
        }
    }
    worst
}

/// The sender runs of a network with their sums along each leaf's chain.
struct Runs<'a> {
    net: &'a LinkNetwork,
    /// Per sender node: `(receiver node, F_sr)`.
    runs: Vec<Vec<(u32, f64)>>,
}

impl<'a> Runs<'a> {
    /// Each node's run sum.
    fn sums(&self) -> Vec<f64> {
        self.runs.iter().map(|r| r.iter().map(|&(_, f)| f).sum()).collect()
    }

    /// Each node's chain sum: its run sum plus its ancestors'.
    fn chains(&self) -> Vec<f64> {
        let sums = self.sums();
        let mut chain = vec![0.0; sums.len()];
        for k in 0..sums.len() {
            chain[k] = sums[k] + self.net.nodes[k].parent.map_or(0.0, |p| chain[p as usize]);
        }
        chain
    }

    /// Scales run `k` by `factor`.
    fn scale(&mut self, k: usize, factor: f64) {
        for e in &mut self.runs[k] {
            e.1 *= factor;
        }
    }

    /// Caps every leaf's chain sum at 1 (module docs).
    fn cap(&mut self) {
        let n = self.net.nodes.len();
        let before = self.sums();
        let chain = self.chains();
        // A leaf's own run takes its excess where it can.
        for k in 0..n {
            if self.net.nodes[k].leaf.is_some() && chain[k] > 1.0 && before[k] > 0.0 {
                self.scale(k, ((before[k] - (chain[k] - 1.0)) / before[k]).max(0.0));
            }
        }
        // What remains: every run scaled by the worst chain below it.
        let chain = self.chains();
        let worst = worst_below(self.net, &chain);
        for (k, &w) in worst.iter().enumerate() {
            if w > 1.0 {
                self.scale(k, 1.0 / w);
            }
        }
    }

    /// A closed scene's runs (module docs, "Closed scenes"): the network's links scaled symmetrically until no
    /// leaf's row sum exceeds 1, then each leaf's row closed by a self-link; returns the runs, the leaves whose
    /// row was over 1 and the self-links' count and largest form factor.
    fn closed(net: &'a LinkNetwork) -> (Runs<'a>, usize, (usize, f64)) {
        let nodes = &net.nodes;
        let n = nodes.len();
        let mut links = net.links.clone();
        // Each node's own links' receiving form factors, and the row sums: those summed down each leaf's chain.
        let owns = |links: &[NetworkLink]| -> Vec<f64> {
            let mut own = vec![0.0; n];
            for l in links {
                own[l.a as usize] += l.f_ab;
                own[l.b as usize] += l.f_ba;
            }
            own
        };
        let rows = |links: &[NetworkLink]| -> Vec<f64> {
            let own = owns(links);
            let mut row = vec![0.0; n];
            for k in 0..n {
                row[k] = own[k] + nodes[k].parent.map_or(0.0, |p| row[p as usize]);
            }
            row
        };
        let scale = |links: &mut [NetworkLink], factor: &[f64]| {
            for l in links.iter_mut() {
                let t = factor[l.a as usize].min(factor[l.b as usize]);
                l.f_ab *= t;
                l.f_ba *= t;
            }
        };
        // A leaf over 1 takes its excess off its own links where it can (both directions, so every link stays
        // reciprocal; a link between two such leaves takes the smaller factor).
        let row = rows(&links);
        let over = (0..n).filter(|&k| nodes[k].leaf.is_some() && row[k] > 1.0).count();
        let own = owns(&links);
        let factor: Vec<f64> = (0..n)
            .map(|k| {
                if nodes[k].leaf.is_some() && row[k] > 1.0 && own[k] > 0.0 {
                    ((own[k] - (row[k] - 1.0)) / own[k]).max(0.0)
                } else {
                    1.0
                }
            })
            .collect();
        scale(&mut links, &factor);
        // What remains: every link scaled by the worst row below its ends, which brings each row within 1 (each
        // term of a leaf's row is scaled by at most the inverse of that row).
        let row = rows(&links);
        let worst = worst_below(net, &row);
        scale(&mut links, &worst.iter().map(|w| 1.0 / w).collect::<Vec<_>>());
        // Shooting form: a link sends `A_a f_ab / A_b` of `b`'s power to `a` and back; reciprocity makes each
        // leaf's chain of run sums equal to its row sum, so a self-link that closes the row closes the chain.
        let mut runs = vec![Vec::new(); n];
        for l in &links {
            let (area_a, area_b) = (nodes[l.a as usize].area, nodes[l.b as usize].area);
            runs[l.b as usize].push((l.a, l.f_ab * area_a / area_b));
            runs[l.a as usize].push((l.b, l.f_ba * area_b / area_a));
        }
        let row = rows(&links);
        let (mut count, mut largest) = (0, 0.0f64);
        for k in 0..n {
            if nodes[k].leaf.is_some() && row[k] < 1.0 {
                let f = 1.0 - row[k];
                runs[k].push((k as u32, f));
                count += 1;
                largest = largest.max(f);
            }
        }
        for run in &mut runs {
            run.sort_by_key(|&(r, _)| r);
        }
        (Runs { net, runs }, over, (count, largest))
    }

    /// The irradiance each leaf node gathers (zero elsewhere) from radiosity `b` per node (leaves set, inner
    /// nodes ignored): every node's power is the sum over the leaves below it, each sender sends `F_sr` of it to
    /// receiver `r`, which spreads it over its area, and a leaf adds up what its chain received.
    fn gather(&self, b: &[Rgb]) -> Vec<Rgb> {
        let nodes = &self.net.nodes;
        let n = nodes.len();
        let mut power = vec![Rgb::ZERO; n];
        for k in (0..n).rev() {
            if nodes[k].leaf.is_some() {
                power[k] = nodes[k].area * b[k];
            }
            if let Some(p) = nodes[k].parent {
                let mine = power[k];
                power[p as usize] += mine;
            }
        }
        let mut irradiance = vec![Rgb::ZERO; n];
        for (s, run) in self.runs.iter().enumerate() {
            for &(r, f) in run {
                irradiance[r as usize] += f * power[s];
            }
        }
        for k in 0..n {
            irradiance[k] /= nodes[k].area;
            if let Some(p) = nodes[k].parent {
                let above = irradiance[p as usize];
                irradiance[k] += above;
            }
        }
        irradiance
    }

    /// The radiosity per node (leaves) of `B = E + rho G(B)` by Jacobi sweeps, `e` and `rho` per node.
    fn solve(&self, e: &[Rgb], rho: &[Rgb]) -> Result<Vec<Rgb>, BakeError> {
        let mut b = e.to_vec();
        for _ in 0..MAX_SWEEPS {
            let g = self.gather(&b);
            let (mut moved, mut total) = (0.0, 0.0);
            for (k, node) in self.net.nodes.iter().enumerate() {
                if node.leaf.is_some() {
                    let new = e[k] + rho[k] * g[k];
                    moved += node.area * max_channel((new - b[k]).abs());
                    total += node.area * max_channel(new);
                    b[k] = new;
                }
            }
            if !(moved.is_finite() && total.is_finite()) {
                break;
            }
            if moved <= HIER_BAKE_TOLERANCE * total {
                return Ok(b);
            }
        }
        Err(BakeError::Input("the hierarchical table's f64 system did not converge".to_owned()))
    }
}

/// What the device computes with, decoded from a parsed table of `net`'s bake into f64: the runs' form factors,
/// each leaf's reflectance, its static base `E_s + rho G_s` (zero without a solved base) and the dynamic
/// emission with every group at its default intensity, per node (zero at inner nodes).
struct DecodedHierarchy<'a> {
    runs: Runs<'a>,
    rho: Vec<Rgb>,
    base: Vec<Rgb>,
    dynamic: Vec<Rgb>,
}

impl<'a> DecodedHierarchy<'a> {
    /// Decodes `table`, baked from `net` (the same nodes in the same order).
    ///
    /// # Errors
    /// [`BakeError::Input`] if the table's nodes are not `net`'s.
    fn new(net: &'a LinkNetwork, table: &HierTable<'_>) -> Result<Self, BakeError> {
        use radiosity_core::codec::{decode_emission_f32, decode_reflectance};
        let n = net.nodes.len();
        if table.node_count() as usize != n {
            return Err(BakeError::Input(format!(
                "the table has {} nodes, the network {n}",
                table.node_count()
            )));
        }
        let mut runs = Runs { net, runs: vec![Vec::new(); n] };
        for (k, run) in runs.runs.iter_mut().enumerate() {
            for position in table.run(k as u32).unwrap_or(0..0) {
                if let Some((r, f)) = table.link(k as u32, position) {
                    run.push((r, f64::from(f.to_f32())));
                }
            }
        }
        let emission = |codes: [u16; 3]| Rgb::from_array(codes.map(|c| f64::from(decode_emission_f32(c))));
        let (mut rho, mut base, mut dynamic) = (vec![Rgb::ZERO; n], vec![Rgb::ZERO; n], vec![Rgb::ZERO; n]);
        let node_of = |leaf: u32| table.leaf_node(leaf).map(|k| k as usize).filter(|&k| k < n);
        for leaf in 0..table.leaf_count() {
            let Some(k) = node_of(leaf) else { continue };
            let codes = table.reflectance(table.material(leaf).unwrap_or(0)).unwrap_or([0; 3]);
            rho[k] = Rgb::from_array(codes.map(|c| f64::from(decode_reflectance(c).to_f32())));
            if table.base_solved() {
                let e = emission(table.base_emission(leaf).unwrap_or([0; 3]));
                let g = emission(table.base_irradiance(leaf).unwrap_or([0; 3]));
                base[k] = e + rho[k] * g;
            }
        }
        for g in 0..table.group_count() {
            let intensity = Rgb::from_array(table.default_intensity(g).unwrap_or([0.0; 3]).map(f64::from));
            for position in table.group_members(g).unwrap_or(0..0) {
                if let Some((m, k)) = table.member(position).and_then(|m| Some((m, node_of(m.leaf)?))) {
                    dynamic[k] += intensity * Rgb::from_array(m.emission.map(f64::from));
                }
            }
        }
        Ok(DecodedHierarchy { runs, rho, base, dynamic })
    }

    /// The decoded system's f64 answer per node (leaves): the static base plus the solve of the dynamic
    /// emission, what the device converges to but for its arithmetic.
    fn answer(&self) -> Result<Vec<Rgb>, BakeError> {
        let mut b = self.runs.solve(&self.dynamic, &self.rho)?;
        for (b, s) in b.iter_mut().zip(&self.base) {
            *b += *s;
        }
        Ok(b)
    }
}

/// Bakes `solution` (of `scene`, from [`crate::hierarchy::solve_hierarchical`]) into a hierarchical table with
/// `bits`-wide form-factor codes; with `transfer`, the table also carries the transfer basis (core's
/// `transfer` module): every leaf's f64 response to each dynamic light group at unit intensity, quantized.
///
/// # Errors
/// [`BakeError::Input`] if the network and the leaves disagree or the table's system does not converge;
/// [`BakeError::BadBits`]; [`BakeError::GroupIdCollision`]; [`BakeError::Write`] / [`BakeError::Parse`] from
/// core's writer and parser.
pub fn bake_hierarchy(
    scene: &Scene,
    solution: &HierarchicalSolution,
    bits: u32,
    transfer: bool,
) -> Result<BakedHierarchy, BakeError> {
    let codec: FfCodec = codec_for_bits(bits)?;
    let net = &solution.network;
    let lighting = PatchLighting::new(scene, &solution.leaves);
    // Table leaves in node order.
    let solution_leaf: Vec<usize> = net.nodes.iter().filter_map(|x| x.leaf.map(|l| l as usize)).collect();
    if solution_leaf.len() != solution.leaves.len() {
        return Err(BakeError::Input(format!(
            "the network has {} leaves, the solution {}",
            solution_leaf.len(),
            solution.leaves.len()
        )));
    }
    let per_node = |v: &[Rgb]| -> Vec<Rgb> {
        net.nodes.iter().map(|x| x.leaf.map_or(Rgb::ZERO, |l| v[l as usize])).collect()
    };
    let rho = per_node(&lighting.rho);
    let e_static = per_node(&lighting.static_emission);
    let mut e_default = e_static.clone();
    for (k, node) in net.nodes.iter().enumerate() {
        if let Some(l) = node.leaf.map(|l| l as usize) {
            if let Some(g) = lighting.group[l] {
                e_default[k] += lighting.default_intensity[g] * lighting.unit_emission[l];
            }
        }
    }

    let open = Runs { net, runs: net.sender_runs() };
    let largest = open
        .chains()
        .iter()
        .zip(&net.nodes)
        .filter(|(_, x)| x.leaf.is_some())
        .map(|(c, _)| *c)
        .fold(0.0, f64::max);
    let before = open.sums();
    let (mut runs, over, self_links) = if solution.stats.closed {
        Runs::closed(net)
    } else {
        let over =
            open.chains().iter().zip(&net.nodes).filter(|(c, x)| x.leaf.is_some() && **c > 1.0).count();
        (open, over, (0, 0.0))
    };
    // A closed scene's chains are 1 but for rounding, which this takes off.
    runs.cap();
    let chain_sum = runs
        .chains()
        .iter()
        .zip(&net.nodes)
        .filter(|(_, x)| x.leaf.is_some())
        .map(|(c, _)| *c)
        .fold(0.0, f64::max);
    let b_static = runs.solve(&e_static, &rho)?;
    let b_default = runs.solve(&e_default, &rho)?;
    let mut b_groups = Vec::with_capacity(lighting.default_intensity.len());
    for g in 0..lighting.default_intensity.len() {
        let e: Vec<Rgb> = net
            .nodes
            .iter()
            .map(|x| match x.leaf.map(|l| l as usize) {
                Some(l) if lighting.group[l] == Some(g) => lighting.unit_emission[l],
                _ => Rgb::ZERO,
            })
            .collect();
        b_groups.push(runs.solve(&e, &rho)?);
    }
    let irradiance = runs.gather(&b_static);
    // The power kept back by the cap: each node's removed share of the power below it.
    let mut power = vec![0.0; net.nodes.len()];
    for k in (0..net.nodes.len()).rev() {
        if net.nodes[k].leaf.is_some() {
            power[k] = net.nodes[k].area * max_channel(b_default[k]);
        }
        if let Some(p) = net.nodes[k].parent {
            let mine = power[k];
            power[p as usize] += mine;
        }
    }
    // In a closed scene the self-links send on what the symmetric cap took off elsewhere: the net change.
    let kept: f64 = before.iter().zip(&runs.sums()).zip(&power).map(|((b, a), p)| (b - a) * p).sum();
    let capped = ChainCap {
        leaves: over,
        largest,
        power_share: if power[0] > 0.0 { kept / power[0] } else { 0.0 },
        self_links: self_links.0,
        largest_self_link: self_links.1,
    };

    let leaves: Vec<PatchSpec> = net
        .nodes
        .iter()
        .enumerate()
        .filter_map(|(k, node)| node.leaf.map(|l| (k, l as usize)))
        .map(|(k, l)| PatchSpec {
            area: solution.leaves[l].area as f32,
            material: u32::try_from(solution.leaves[l].material).unwrap_or(u32::MAX),
            base_emission: lighting.static_emission[l].as_vec3().to_array(),
            base_irradiance: irradiance[k].as_vec3().to_array(),
        })
        .collect();
    let nodes: Vec<NodeSpec> = net.nodes.iter().map(|x| NodeSpec { parent: x.parent }).collect();
    let names: Vec<String> =
        lighting.dynamic_groups.iter().map(|&g| scene.light_groups[g].name.clone()).collect();
    let ids = group_ids(&names)?;
    let mut members: Vec<Vec<MemberSpec>> = vec![Vec::new(); ids.len()];
    for (t, &l) in solution_leaf.iter().enumerate() {
        if let Some(g) = lighting.group[l] {
            members[g].push(MemberSpec {
                patch: t as u32,
                emission: lighting.unit_emission[l].as_vec3().to_array(),
            });
        }
    }
    let groups: Vec<GroupSpec<'_>> = ids
        .iter()
        .zip(&members)
        .zip(&lighting.default_intensity)
        .map(|((&id, m), &d)| GroupSpec { id, default_intensity: d.as_vec3().to_array(), members: m })
        .collect();
    let mut row_start = Vec::with_capacity(runs.runs.len() + 1);
    let (mut receiver, mut form_factor) = (Vec::new(), Vec::new());
    row_start.push(0u32);
    for run in &runs.runs {
        for &(r, f) in run {
            receiver.push(r);
            form_factor.push(f as f32);
        }
        row_start.push(receiver.len() as u32);
    }
    let materials: Vec<[f32; 3]> =
        scene.materials.iter().map(|m| m.reflectance.as_vec3().to_array()).collect();
    let leaf_nodes: Vec<usize> = (0..net.nodes.len()).filter(|&k| net.nodes[k].leaf.is_some()).collect();
    // The transfer basis, leaf-major: each leaf's response to every group at unit intensity.
    let responses: Option<Vec<[f32; 3]>> = transfer.then(|| {
        leaf_nodes.iter().flat_map(|&k| b_groups.iter().map(move |b| b[k].as_vec3().to_array())).collect()
    });
    let spec = HierSpec {
        nodes: &nodes,
        leaves: &leaves,
        materials: &materials,
        groups: &groups,
        links: RowsSpec { row_start: &row_start, receiver: &receiver, form_factor: &form_factor },
        codec,
        base_solved: true,
        fingerprint: scene_fingerprint(&solution.leaves),
        transfer: responses.as_deref(),
    };
    let mut table = vec![0u8; hier_required_len(&spec).map_err(BakeError::Write)?];
    let written = write_hier_table(&spec, &mut table).map_err(BakeError::Write)?;
    table.truncate(written);
    HierTable::parse(&table).map_err(BakeError::Parse)?;
    Ok(BakedHierarchy {
        radiosity: leaf_nodes.iter().map(|&k| b_default[k]).collect(),
        static_radiosity: leaf_nodes.iter().map(|&k| b_static[k]).collect(),
        responses: b_groups.iter().map(|b| leaf_nodes.iter().map(|&k| b[k]).collect()).collect(),
        counts: (net.nodes.len(), solution_leaf.len(), net.links.len()),
        capped,
        chain_sum,
        solution_leaf,
        table,
    })
}

/// Work units per frame of the cold relight [`HierBakeSummary::measure`] runs.
pub const SUMMARY_FRAME_UNITS: u32 = 10_000;

/// Most frames of that relight.
const SUMMARY_MAX_FRAMES: usize = 100_000;

/// The relight's convergence tolerance (core's unshot power per node) as a share of the power the lights emit:
/// small enough that what remains unshot is far below the 16-bit codes' error floor.
pub const SUMMARY_TOLERANCE: f64 = 1e-7;

/// What a hierarchical bake made and what it costs the device: sizes, the chain cap, and core's hierarchical
/// solver (f32) relighting it from cold (every light group switched on at its default intensity) in frames of
/// [`SUMMARY_FRAME_UNITS`] work units, judged against the f64 answer of the table's own system.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HierBakeSummary {
    /// Tree nodes.
    pub nodes: usize,
    /// Leaves (the elements the device gives radiosity for).
    pub leaves: usize,
    /// Links (each an entry in both ends' runs).
    pub links: usize,
    /// Table bytes.
    pub bytes: usize,
    /// RAM of core's solver buffers for the table in f32 (`HierBufferSizes::bytes`).
    pub ram_f32: usize,
    /// Leaves whose chain summed to more than 1, and what the cap changed.
    pub cap_leaves: usize,
    /// The largest chain sum before the cap.
    pub cap_largest: f64,
    /// In a closed scene, the leaves whose row the bake closed with a self-link (module docs, "Closed scenes").
    pub self_links: usize,
    /// The largest of those self-links' form factors.
    pub largest_self_link: f64,
    /// The power the cap keeps from being sent on, as a share of all the leaves' power.
    pub cap_power_share: f64,
    /// The table system's f64 answer against the hierarchical solve's: area-weighted relative L1 difference
    /// (largest channel), what the cap changed (in a closed scene, the table's closure against the solve's: module
    /// docs, "Closed scenes").
    pub cap_difference: f64,
    /// Whether the hierarchical solve found the scene closed and scaled each leaf's gathered light by its row
    /// sum (`hierarchy`, "Closed scenes"); the table closes the rows with self-links instead.
    pub closed: bool,
    /// Work units until the device's area-weighted relative L1 error (largest channel) was below 1%, if it got
    /// there.
    pub units_to_one_percent: Option<u64>,
    /// Work units until the device converged (every node's unshot power within `SUMMARY_TOLERANCE` of the
    /// emitted power).
    pub units_to_converge: Option<u64>,
    /// The converged device's error (same measure): the codes' and f32's floor.
    pub error_floor: Option<f64>,
    /// The quantization component (same measure): the f64 answer of the table's decoded codes (form factors,
    /// reflectances, static base; areas and emissions as the table's f32) against the f64 answer of the system
    /// they were quantized from. The device floor adds f32's arithmetic to it.
    pub quantization: f64,
    /// Shots and link entries walked until convergence.
    pub shots: u32,
    /// See `shots`.
    pub links_walked: u64,
    /// With a transfer basis: core's f32 transfer relight at the default intensities, its work units
    /// (`leaves x (groups + 1)`) and its error (same measure) against the table system's f64 answer.
    pub transfer: Option<(u32, f64)>,
}

/// Area-weighted relative L1 difference (largest channel) of `got` against `want`.
fn relative_l1(area: &[f64], got: impl Iterator<Item = Rgb>, want: &[Rgb]) -> f64 {
    let (mut diff, mut total) = (0.0, 0.0);
    for ((a, g), w) in area.iter().zip(got).zip(want) {
        diff += a * max_channel((g - *w).abs());
        total += a * max_channel(*w);
    }
    if total > 0.0 {
        diff / total
    } else {
        0.0
    }
}

impl HierBakeSummary {
    /// Measures `baked` (from `solution`) as the type's docs say.
    ///
    /// # Errors
    /// [`BakeError::Parse`] if the table does not parse, [`BakeError::Input`] if core's solver refuses it.
    pub fn measure(baked: &BakedHierarchy, solution: &HierarchicalSolution) -> Result<Self, BakeError> {
        use radiosity_core::{Config, HierBufferSizes, HierOwnedBuffers, HierSolver, Outcome};
        let table = HierTable::parse(&baked.table).map_err(BakeError::Parse)?;
        let emitted: f64 =
            solution.leaves.iter().zip(&solution.emission).map(|(p, e)| p.area * max_channel(*e)).sum();
        let area: Vec<f64> = baked.solution_leaf.iter().map(|&l| solution.leaves[l].area).collect();
        let hierarchy: Vec<Rgb> = baked.solution_leaf.iter().map(|&l| solution.b[l]).collect();
        let mut buffers = HierOwnedBuffers::<f32>::for_table(&table);
        let mut solver = HierSolver::new(
            &table,
            buffers.buffers(),
            Config { tolerance: (SUMMARY_TOLERANCE * emitted) as f32, overshoot: 0 },
        )
        .map_err(|e| BakeError::Input(format!("core's hierarchical solver refuses the table: {e:?}")))?;
        let device = |s: &HierSolver<'_, f32>| -> Vec<Rgb> {
            let mut b = vec![[0.0f32; 3]; baked.radiosity.len()];
            s.radiosity_into(&mut b);
            b.iter().map(|b| Rgb::new(f64::from(b[0]), f64::from(b[1]), f64::from(b[2]))).collect()
        };
        let (mut units, mut to_one, mut converged) = (0u64, None, None);
        for _ in 0..SUMMARY_MAX_FRAMES {
            let outcome = solver.step(SUMMARY_FRAME_UNITS);
            let used = match outcome {
                Outcome::Converged { used } => used,
                _ => SUMMARY_FRAME_UNITS,
            };
            units += u64::from(used);
            if to_one.is_none() && relative_l1(&area, device(&solver).into_iter(), &baked.radiosity) < 0.01 {
                to_one = Some(units);
            }
            if matches!(outcome, Outcome::Converged { .. }) {
                converged = Some(units);
                break;
            }
        }
        let decoded = baked.decoded_radiosity(&solution.network)?;
        let quantization = relative_l1(&area, decoded.into_iter(), &baked.radiosity);
        let transfer = if table.has_transfer() {
            let intensity: Vec<[f32; 3]> =
                (0..table.group_count()).map(|g| table.default_intensity(g).unwrap_or([0.0; 3])).collect();
            let mut b = vec![[0.0f32; 3]; baked.radiosity.len()];
            let units = radiosity_core::relight_transfer(&table, &intensity, &mut b)
                .map_err(|e| BakeError::Input(format!("core's transfer relight refuses the table: {e}")))?;
            let got = b.iter().map(|b| Rgb::new(f64::from(b[0]), f64::from(b[1]), f64::from(b[2])));
            Some((units, relative_l1(&area, got, &baked.radiosity)))
        } else {
            None
        };
        Ok(HierBakeSummary {
            transfer,
            nodes: baked.counts.0,
            leaves: baked.counts.1,
            links: baked.counts.2,
            bytes: baked.table.len(),
            ram_f32: HierBufferSizes::of(&table).bytes::<f32>(),
            cap_leaves: baked.capped.leaves,
            cap_largest: baked.capped.largest,
            self_links: baked.capped.self_links,
            largest_self_link: baked.capped.largest_self_link,
            cap_power_share: baked.capped.power_share,
            cap_difference: relative_l1(&area, baked.radiosity.iter().copied(), &hierarchy),
            closed: solution.stats.closed,
            units_to_one_percent: to_one,
            units_to_converge: converged,
            error_floor: converged.map(|_| relative_l1(&area, device(&solver).into_iter(), &baked.radiosity)),
            quantization,
            shots: solver.shots(),
            links_walked: solver.links(),
        })
    }
}

impl std::fmt::Display for HierBakeSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let opt = |v: Option<u64>| v.map_or_else(|| "not reached".to_owned(), |u| format!("{u} units"));
        writeln!(f, "hierarchical table {} nodes, {} leaves, {} links", self.nodes, self.leaves, self.links)?;
        writeln!(
            f,
            "table size         {} bytes ({:.0} per leaf); solver RAM {} bytes in f32",
            self.bytes,
            self.bytes as f64 / self.leaves.max(1) as f64,
            self.ram_f32
        )?;
        writeln!(
            f,
            "chain cap          {} leaves over 1 (largest {:.4}), {:.2e} of the power kept back, answer moved \
             {:.2e}{}",
            self.cap_leaves,
            self.cap_largest,
            self.cap_power_share,
            self.cap_difference,
            if self.closed { " (and the closed scene's rows closed differently from the solve's, below)" } else { "" }
        )?;
        if self.closed {
            writeln!(
                f,
                "closure            the scene is closed: {} leaves' rows closed by a self-link (largest {:.4}), \
                 where the solve scales what each leaf gathers",
                self.self_links, self.largest_self_link
            )?;
        }
        writeln!(
            f,
            "device (f32)       cold lights-on in frames of {SUMMARY_FRAME_UNITS} units: 1% error after {}, \
             converged after {}",
            opt(self.units_to_one_percent),
            opt(self.units_to_converge)
        )?;
        write!(
            f,
            "device floor       {} ({} shots, {} link entries walked); of which quantization {:.2e} (f64 \
             answer of the decoded codes)",
            self.error_floor.map_or_else(|| "not converged".to_owned(), |e| format!("{e:.2e}")),
            self.shots,
            self.links_walked,
            self.quantization
        )?;
        if let Some((units, error)) = self.transfer {
            write!(f, "\ntransfer relight   {units} units (leaves x (groups + 1)), error {error:.2e} (f32)")?;
        }
        Ok(())
    }
}
