//! The scene fingerprint: the bake stores `bake::scene_fingerprint` of its patches in the table header, core
//! and inspect read it back, and any change to the patch list changes it.

use std::path::Path;

use radiosity_core::Table;
use radiosity_host::bake::{bake, scene_fingerprint, BakeInput, BakeOptions};
use radiosity_host::inspect::inspect;
use radiosity_host::pipeline::{prepare, PrepareOptions, Prepared};

/// The Cornell box with one patch per face (fast; the fingerprint does not depend on accuracy).
fn cornell_faces() -> Prepared {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.obj");
    let options = PrepareOptions::quiet(true, 4, 4);
    prepare(&path, &options).unwrap()
}

#[test]
fn bake_stores_the_fingerprint_and_inspect_shows_it() {
    let p = cornell_faces();
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &BakeOptions::default()).unwrap();
    let expected = scene_fingerprint(&p.patches);
    assert_ne!(expected, 0);
    assert_eq!(Table::parse(&baked.table).unwrap().fingerprint(), expected);
    assert_eq!(baked.report.fingerprint, expected);
    let report = inspect(&baked.table).unwrap();
    assert_eq!(report.fingerprint, expected);
    assert!(report.to_string().contains(&format!("{expected:#018x}")), "{report}");
}

#[test]
fn any_change_to_the_patch_list_changes_the_fingerprint() {
    let p = cornell_faces();
    let base = scene_fingerprint(&p.patches);
    assert_eq!(scene_fingerprint(&p.patches.clone()), base, "deterministic");

    let mut moved = p.patches.clone();
    moved[3].centroid.x += moved[3].centroid.x.abs().max(1.0) * 1e-12;
    assert_ne!(scene_fingerprint(&moved), base, "a centroid moved by one part in 1e12");

    let mut resized = p.patches.clone();
    resized[0].area *= 1.0 + 1e-15;
    assert_ne!(scene_fingerprint(&resized), base, "an area changed in its last bits");

    let mut turned = p.patches.clone();
    turned[5].normal = -turned[5].normal;
    assert_ne!(scene_fingerprint(&turned), base, "a normal flipped");

    let mut recoloured = p.patches.clone();
    recoloured[7].material = (recoloured[7].material + 1) % p.scene.materials.len();
    assert_ne!(scene_fingerprint(&recoloured), base, "a material changed");

    let mut reordered = p.patches.clone();
    reordered.swap(1, 2);
    assert_ne!(scene_fingerprint(&reordered), base, "two patches swapped");

    let fewer = &p.patches[..p.patches.len() - 1];
    assert_ne!(scene_fingerprint(fewer), base, "a patch removed");

    // The sign of a zero coordinate is not part of the scene.
    let mut signed = p.patches.clone();
    let zeroed = signed.iter().position(|q| q.normal.x == 0.0).expect("an axis-aligned patch");
    signed[zeroed].normal.x = -0.0;
    assert_eq!(scene_fingerprint(&signed), base, "-0.0 hashes as 0.0");
}
