//! Adaptive refinement: scores that estimate how much each patch's radiosity changes across it, the choice of
//! patches to split within the budget, and the split itself.

use std::collections::HashSet;

use super::adjacency::{adjacency, touches};
use super::pieces::{centroid_quads, make_patch, quad_grid, triangle_grid};
use super::MeshError;
use crate::patch::Patch;
use crate::rgb::Rgb;
use crate::scene::{Polygon, Scene};

/// Splits the patches listed in `which` into children; the others are kept. Each split patch is replaced, in
/// place, by its children, so patches stay in face order (indices after a split patch shift).
///
/// A triangle gives 4 similar triangles (edge midpoints), a quadrilateral a 2 x 2 grid of its bilinear
/// parametrisation, a polygon with more vertices one quadrilateral per vertex (centroid, edge midpoints); all
/// convex. Children keep the parent's `face`, `material` and normal, and their areas add up to the parent's.
/// Repeated indices in `which` split a patch once.
///
/// # Errors
/// [`MeshError::NoSuchPatch`] if an index is out of range, [`MeshError::ZeroAreaPatch`] if a child degenerates.
pub fn refine(patches: &[Patch], which: &[usize]) -> Result<Vec<Patch>, MeshError> {
    let mut selected = HashSet::with_capacity(which.len());
    for &i in which {
        if i >= patches.len() {
            return Err(MeshError::NoSuchPatch { index: i, len: patches.len() });
        }
        selected.insert(i);
    }
    let mut out = Vec::with_capacity(patches.len() + 3 * selected.len());
    let mut pieces = Vec::new();
    for (i, p) in patches.iter().enumerate() {
        if !selected.contains(&i) {
            out.push(p.clone());
            continue;
        }
        let v = &p.vertices;
        pieces.clear();
        match v.len() {
            3 => triangle_grid(v[0], v[1], v[2], 2, &mut pieces),
            4 => quad_grid(v, 2, 2, &mut pieces),
            _ => {
                let poly = Polygon::with_normal(v.clone(), p.normal)
                    .ok_or(MeshError::ZeroAreaPatch { face: p.face })?;
                for q in centroid_quads(&poly) {
                    pieces.push(q.ok_or(MeshError::ZeroAreaPatch { face: p.face })?.vertices);
                }
            }
        }
        for vertices in pieces.drain(..) {
            out.push(make_patch(p.face, p.material, vertices, p.normal)?);
        }
    }
    Ok(out)
}

/// Adaptive refinement passes when the scene's TOML file sets none.
pub const DEFAULT_REFINE_PASSES: usize = 2;
/// Refinement tolerance when the scene's TOML file sets none: a patch is a candidate when light changes across it
/// by more than this fraction of the scene's mean radiosity.
pub const DEFAULT_REFINE_TOLERANCE: f64 = 0.1;

/// How adaptive refinement chooses patches to split (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineOptions {
    /// Refinement passes (0: keep the uniform mesh).
    pub passes: usize,
    /// A patch is a candidate when its estimated radiosity change exceeds `tolerance` times the area-weighted
    /// mean radiosity of the non-emitting patches.
    pub tolerance: f64,
}

impl RefineOptions {
    /// The scene's own settings (its TOML file), or [`DEFAULT_REFINE_PASSES`] and [`DEFAULT_REFINE_TOLERANCE`].
    #[must_use]
    pub fn for_scene(scene: &Scene) -> RefineOptions {
        RefineOptions {
            passes: scene.meshing.refine_passes.unwrap_or(DEFAULT_REFINE_PASSES),
            tolerance: scene.meshing.refine_tolerance.unwrap_or(DEFAULT_REFINE_TOLERANCE),
        }
    }
}

/// What one solved pass tells refinement, per patch. All radiosities are luminance-like: the mean of the three
/// channels (W/m^2).
#[derive(Clone, Copy, Debug)]
pub struct RefineInput<'a> {
    /// The current patches.
    pub patches: &'a [Patch],
    /// Radiosity per patch (the f64 reference solution of this mesh).
    pub radiosity: &'a [Rgb],
    /// Emission per patch.
    pub emission: &'a [Rgb],
    /// Reflectance per patch.
    pub reflectance: &'a [Rgb],
    /// The form factors of this mesh, their flags marking partly visible pairs (shadow boundaries).
    pub form_factors: &'a crate::patch::FormFactorMatrix,
}

/// Why a patch is worth splitting: three estimates of how much its radiosity changes across it (W/m^2).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefineScore {
    /// Largest radiosity difference to a neighbour of the same face (the radiosity gradient).
    pub gradient: f64,
    /// Light the patch reflects from partly visible patches, `rho_i sum_j F_ij B_j` over partly visible pairs:
    /// how much a shadow boundary crossing it can change its radiosity.
    pub shadow: f64,
    /// Contact edges: for a patch touched by another face along a line in its plane (a block standing on the
    /// floor, two walls meeting), `rho_i max_j (1/2 - F_ij) |B_j - H_i|`, with `H_i` the irradiance: at the contact
    /// line the other face fills half the view (a half-plane's form factor is 1/2), far from it only `F_ij`.
    pub contact: f64,
}

impl RefineScore {
    /// The largest of the three estimates.
    #[must_use]
    pub fn change(&self) -> f64 {
        self.gradient.max(self.shadow).max(self.contact)
    }
}

/// The luminance-like value refinement compares: the mean of the three channels.
fn channel_mean(c: &Rgb) -> f64 {
    c.element_sum() / 3.0
}

/// The [`RefineScore`] of every patch.
///
/// # Panics
/// If the slices and the matrix do not all have one entry per patch.
#[must_use]
pub fn refine_scores(input: &RefineInput<'_>) -> Vec<RefineScore> {
    let n = input.patches.len();
    assert!(
        input.radiosity.len() == n
            && input.emission.len() == n
            && input.reflectance.len() == n
            && input.form_factors.n() == n,
        "one value per patch"
    );
    let b: Vec<f64> = input.radiosity.iter().map(channel_mean).collect();
    let neighbours = adjacency(input.patches);
    let ff = input.form_factors;
    (0..n)
        .map(|i| {
            let rho = channel_mean(&input.reflectance[i]);
            let gradient = neighbours[i].iter().map(|&j| (b[i] - b[j]).abs()).fold(0.0, f64::max);
            let mut shadow = 0.0;
            let mut irradiance = 0.0;
            for ((j, f), &partly_visible) in ff.row(i).zip(ff.row_flags(i)) {
                irradiance += f * b[j];
                if partly_visible {
                    shadow += f * b[j];
                }
            }
            let mut contact = 0.0f64;
            for (j, f) in ff.row(i) {
                if touches(&input.patches[i], &input.patches[j]) {
                    contact = contact.max((0.5 - f).max(0.0) * (b[j] - irradiance).abs());
                }
            }
            RefineScore { gradient, shadow: rho * shadow, contact: rho * contact }
        })
        .collect()
}

/// Chooses the patches to split in one refinement pass: those whose [`RefineScore::change`] exceeds
/// `tolerance` times the area-weighted mean radiosity of the non-emitting patches (of all patches if all emit), in decreasing order of
/// `change * sqrt(area)` (the area-weighted L2 error a constant patch makes is about the change across it times
/// the square root of its area), as long as the patches they add keep the mesh within `budget`.
///
/// # Panics
/// If `scores` or `input` do not match `input.patches`.
#[must_use]
pub fn select_for_refinement(
    input: &RefineInput<'_>,
    scores: &[RefineScore],
    tolerance: f64,
    budget: usize,
) -> Vec<usize> {
    let patches = input.patches;
    let mut candidates = candidates(input, scores, tolerance);
    candidates.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let mut count = patches.len();
    let mut chosen = Vec::new();
    for (i, _) in candidates {
        let added = children(&patches[i]) - 1;
        if count + added <= budget {
            count += added;
            chosen.push(i);
        }
    }
    chosen.sort_unstable();
    chosen
}

/// How many patches are worth splitting: those [`select_for_refinement`] would choose from with no budget
/// (their change above `tolerance` times the mean radiosity). Fewer chosen than this means the budget stopped
/// refinement; none means the mesh resolves the light to the tolerance.
///
/// # Panics
/// If `scores` or `input` do not match `input.patches`.
#[must_use]
pub fn refinement_candidates(input: &RefineInput<'_>, scores: &[RefineScore], tolerance: f64) -> usize {
    candidates(input, scores, tolerance).len()
}

/// The patches whose change exceeds `tolerance` times the reference radiosity, with their priority
/// `change * sqrt(area)`, in patch order.
fn candidates(input: &RefineInput<'_>, scores: &[RefineScore], tolerance: f64) -> Vec<(usize, f64)> {
    let patches = input.patches;
    assert_eq!(scores.len(), patches.len(), "one score per patch");
    // Mean radiosity of the non-emitting patches (of all patches if every patch emits, as in a white furnace).
    let mean = |emitting_too: bool| {
        let (mut weighted, mut area) = (0.0, 0.0);
        for (i, p) in patches.iter().enumerate() {
            if emitting_too || channel_mean(&input.emission[i]) == 0.0 {
                weighted += channel_mean(&input.radiosity[i]) * p.area;
                area += p.area;
            }
        }
        if area > 0.0 {
            weighted / area
        } else {
            0.0
        }
    };
    let reference = if patches.iter().enumerate().any(|(i, _)| channel_mean(&input.emission[i]) == 0.0) {
        mean(false)
    } else {
        mean(true)
    };
    let threshold = tolerance * reference;
    scores
        .iter()
        .enumerate()
        .filter(|(_, s)| s.change() > threshold)
        .map(|(i, s)| (i, s.change() * patches[i].area.sqrt()))
        .collect()
}

/// Number of children [`refine`] makes of a patch.
fn children(p: &Patch) -> usize {
    match p.vertices.len() {
        3 | 4 => 4,
        n => Polygon::with_normal(p.vertices.clone(), p.normal).map_or(n, |poly| centroid_quads(&poly).len()),
    }
}

/// The patch areas of a mesh, sorted ascending: the patch-size distribution (e.g. for a histogram of an adaptive
/// mesh, where small patches sit where light changes fast).
#[must_use]
pub fn patch_area_distribution(patches: &[Patch]) -> Vec<f64> {
    let mut areas: Vec<f64> = patches.iter().map(|p| p.area).collect();
    areas.sort_by(f64::total_cmp);
    areas
}
