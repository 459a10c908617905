//! What the module's unit tests share: the Cornell box's face polygons with their lighting and the estimator's
//! rules, and the ancestor test.

use super::tree::{Tree, NONE};
use crate::formfactor::{ElementRules, FormFactorOptions};
use crate::lighting::PatchLighting;
use crate::mesh::{mesh, MeshOptions};
use crate::patch::Patch;
use crate::scene::Scene;

/// The published Cornell box as tree roots (its face polygons, unsubdivided), their lighting, and the default
/// estimator rules (no progress output).
pub(super) fn cornell_polygons() -> (Vec<Patch>, PatchLighting, ElementRules) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.obj");
    let scene = Scene::load(&path).unwrap();
    let roots = mesh(&scene, &MeshOptions { patch_budget: usize::MAX, ..MeshOptions::no_subdivide(&scene) })
        .unwrap()
        .patches;
    let lighting = PatchLighting::new(&scene, &roots);
    let rules =
        ElementRules::new(&FormFactorOptions { progress: false, ..FormFactorOptions::default() }).unwrap();
    (roots, lighting, rules)
}

/// Whether node `k` is `c` or lies below it.
pub(super) fn within(tree: &Tree, k: u32, c: u32) -> bool {
    let mut k = k;
    while k != NONE {
        if k == c {
            return true;
        }
        k = tree.nodes[k as usize].parent;
    }
    false
}
