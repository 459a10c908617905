//! Meshing: one patch per face, uniform subdivision (edge limit, budget, areas, normals, convexity), adjacency
//! and refinement.

use std::path::PathBuf;

use glam::DVec3;
use proptest::prelude::*;
use radiosity_host::mesh::{adjacency, mesh, refine, MeshError, MeshOptions, RepairReport};
use radiosity_host::patch::Patch;
use radiosity_host::rgb::Rgb;
use radiosity_host::scene::{Face, Material, MeshingLimits, Polygon, Scene};

fn load(name: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../scenes/{name}.obj"));
    Scene::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Largest coordinate magnitude in the scene: absolute rounding of a computed vertex is a few `eps` times it.
fn coord_scale(s: &Scene) -> f64 {
    s.faces.iter().flat_map(|f| f.vertices.iter()).map(|v| v.abs().max_element()).fold(0.0, f64::max)
}

/// Bound on `|sum of patch areas - face area|` for `n` patches with edges up to `edge`: each vertex is off by at
/// most `delta = 4 eps C` (interpolation, `C` the coordinate scale), moving each patch's area by at most its
/// perimeter (4 edges of a quadrilateral, the most vertices a piece has here: `<= 4 edge delta`), and each area is
/// computed with a relative rounding error of a few `eps` (`8 eps` of the total over all patches).
fn area_tol(n: usize, edge: f64, c: f64, area: f64) -> f64 {
    let delta = 4.0 * f64::EPSILON * c;
    n as f64 * 4.0 * edge * delta + 8.0 * f64::EPSILON * area
}

/// Checks every patch against its face: normal, plane, convexity, edge limit; and per face that the areas add up
/// (to the face's area less what repair culled, for a repaired mesh).
fn check_mesh(s: &Scene, patches: &[Patch], edge: f64) {
    check_repaired_mesh(s, patches, edge, None);
}

/// [`check_mesh`] for a mesh that `repair` changed.
fn check_repaired_mesh(s: &Scene, patches: &[Patch], edge: f64, repair: Option<&RepairReport>) {
    let c = coord_scale(s);
    let tol = 8.0 * f64::EPSILON * c;
    for (k, p) in patches.iter().enumerate() {
        let face = &s.faces[p.face];
        assert_eq!(p.material, face.material);
        // The polygon of the face this patch lies on: the one with the same normal (split faces have several).
        let poly = face.polygons.iter().find(|q| q.normal == p.normal).unwrap_or_else(|| {
            panic!("patch {k}: normal {} is none of face {}'s polygon normals", p.normal, p.face)
        });
        let n = p.vertices.len();
        for i in 0..n {
            let (a, b, d) = (p.vertices[i], p.vertices[(i + 1) % n], p.vertices[(i + 2) % n]);
            assert!((a - poly.centroid).dot(poly.normal).abs() <= tol, "patch {k} leaves its face's plane");
            assert!(a.distance(b) <= edge + tol, "patch {k}: edge {} > limit {edge}", a.distance(b));
            assert!(
                (b - a).cross(d - b).dot(p.normal) > -tol * edge,
                "patch {k} is not convex at vertex {i}"
            );
            // Inside the face polygon: on the inner side of each of its (convex) edges. The cross product is the
            // signed distance from the edge's line times the edge's length; a vertex position carries a rounding
            // error of a few ulps of the coordinates (`tol`), so the distance may be `-tol` at worst.
            let m = poly.vertices.len();
            for j in 0..m {
                let (q0, q1) = (poly.vertices[j], poly.vertices[(j + 1) % m]);
                assert!(
                    (q1 - q0).cross(a - q0).dot(poly.normal) >= -tol * (q1 - q0).length(),
                    "patch {k} leaves face {}",
                    p.face
                );
            }
        }
        let recomputed: DVec3 = (1..n - 1)
            .map(|i| 0.5 * (p.vertices[i] - p.vertices[0]).cross(p.vertices[i + 1] - p.vertices[0]))
            .sum();
        assert!((recomputed.dot(p.normal) - p.area).abs() <= 8.0 * f64::EPSILON * c * c, "patch {k}: area");
    }
    for f in &s.faces {
        let mine: Vec<&Patch> = patches.iter().filter(|p| p.face == f.index).collect();
        assert!(!mine.is_empty(), "face {} has no patch", f.index);
        let sum: f64 = mine.iter().map(|p| p.area).sum();
        let culled =
            repair.and_then(|r| r.faces.iter().find(|x| x.face == f.index)).map_or(0.0, |x| x.culled_area);
        let allowed = area_tol(mine.len(), edge.min(f.polygons[0].diameter()), c, f.area);
        assert!(
            (sum + culled - f.area).abs() <= allowed,
            "face {}: patch areas {sum} + culled {culled} vs face {} (allowed {allowed})",
            f.index,
            f.area
        );
    }
    // Patches come in face order.
    assert!(patches.windows(2).all(|w| w[0].face <= w[1].face));
}

#[test]
fn no_subdivide_gives_one_patch_per_face() {
    let s = load("cornell-box");
    // The faces as loaded (repair, which cuts the floor around the blocks, has its own tests in repair.rs).
    let m = mesh(&s, &MeshOptions { repair: false, ..MeshOptions::no_subdivide(&s) }).unwrap();
    // 19 faces; the non-planar red wall (face 18, last) is two triangles.
    assert_eq!(m.patches.len(), 20);
    for (k, p) in m.patches.iter().enumerate().take(18) {
        let f = &s.faces[k];
        assert_eq!((p.face, p.material), (k, f.material));
        assert_eq!(p.vertices, f.vertices);
        assert_eq!(p.normal, f.normal);
        assert_eq!(p.area, f.area);
    }
    assert_eq!((m.patches[18].face, m.patches[19].face), (18, 18));
    assert_eq!(m.patches[18].vertices, s.faces[18].polygons[0].vertices);
    assert_eq!(m.patches[19].vertices, s.faces[18].polygons[1].vertices);
    check_mesh(&s, &m.patches, f64::INFINITY);
    // Repaired (the default), only the floor changes: one patch per piece it keeps.
    let r = mesh(&s, &MeshOptions::no_subdivide(&s)).unwrap();
    let report = r.repair.as_ref().expect("repair is on by default");
    assert_eq!(report.faces.len(), 1);
    assert_eq!(
        r.patches.iter().filter(|p| p.face != 0).cloned().collect::<Vec<_>>(),
        m.patches[1..].to_vec()
    );
    assert_eq!(r.patches.iter().filter(|p| p.face == 0).count(), report.faces[0].polygons);
    check_repaired_mesh(&s, &r.patches, f64::INFINITY, Some(report));
    for name in ["facing-squares", "perpendicular-squares", "furnace", "cornell-box-closed"] {
        let s = load(name);
        let m = mesh(&s, &MeshOptions::no_subdivide(&s)).unwrap();
        let polygons: usize = s.faces.iter().map(|f| f.polygons.len()).sum();
        assert_eq!(m.patches.len(), polygons, "{name}");
        check_mesh(&s, &m.patches, f64::INFINITY);
    }
}

#[test]
fn uniform_subdivision_respects_the_edge_limit() {
    let s = load("cornell-box");
    // The faces as loaded, so that the counts below are those of the published faces.
    let opts = MeshOptions { repair: false, ..MeshOptions::for_scene(&s) };
    assert_eq!((opts.max_patch_edge, opts.patch_budget), (100.0, 1000));
    let m = mesh(&s, &opts).unwrap();
    assert_eq!(m.max_patch_edge, 100.0, "the budget holds the mesh at the requested limit");
    assert!(m.patches.len() <= 1000);
    check_mesh(&s, &m.patches, 100.0);
    // The floor (552.8 / 549.6 x 559.2) is a 6 x 6 grid, the light (130 x 105) a 2 x 2 one. Each half of the
    // split red wall (legs ~550 and ~559, hypotenuse 783.5) would be 8 x 8 = 64 similar triangles; its three
    // centroid quadrilaterals need fewer.
    let red = m.patches.iter().filter(|p| p.face == 18).count();
    assert!(red < 2 * 64, "red wall: {red} patches");
    assert_eq!(m.patches.iter().filter(|p| p.face == 0).count(), 36);
    assert_eq!(m.patches.iter().filter(|p| p.face == 1).count(), 4);
    // A smaller limit gives more, smaller patches, still exact.
    let fine = mesh(&s, &MeshOptions { max_patch_edge: 40.0, patch_budget: 100_000, ..opts }).unwrap();
    assert!(fine.patches.len() > m.patches.len());
    // Repaired, the floor's pieces are subdivided alike.
    let r = mesh(&s, &MeshOptions::for_scene(&s)).unwrap();
    assert_eq!(r.max_patch_edge, 100.0);
    check_repaired_mesh(&s, &r.patches, 100.0, r.repair.as_ref());
    check_mesh(&s, &fine.patches, 40.0);
}

#[test]
fn the_budget_raises_the_edge_limit_or_fails() {
    let s = load("cornell-box");
    // The faces as loaded: 20 polygons.
    let opts = MeshOptions { patch_budget: 200, repair: false, ..MeshOptions::for_scene(&s) };
    let m = mesh(&s, &opts).unwrap();
    assert!(m.patches.len() <= 200, "{} patches", m.patches.len());
    assert!(m.max_patch_edge > 100.0);
    check_mesh(&s, &m.patches, m.max_patch_edge);
    // The limit found is the smallest that fits (bisection to a relative 1e-12): just below it, the mesh is over.
    let below =
        MeshOptions { max_patch_edge: m.max_patch_edge * (1.0 - 1e-6), patch_budget: usize::MAX, ..opts };
    assert!(mesh(&s, &below).unwrap().patches.len() > 200);
    // One patch per face polygon (19 faces, the red wall as 2 triangles) is the least.
    let exact = mesh(&s, &MeshOptions { patch_budget: 20, ..opts }).unwrap();
    assert_eq!(exact.patches.len(), 20);
    let e = mesh(&s, &MeshOptions { patch_budget: 19, ..opts }).unwrap_err();
    assert_eq!(e, MeshError::BudgetTooSmall { budget: 19, needed: 20, faces: 19 });
    assert!(e.to_string().contains("patch budget 19 cannot hold one patch per face"), "{e}");
    // An absurdly small limit only means "as fine as the budget allows": the count saturates, nothing overflows.
    let tiny = mesh(&s, &MeshOptions { max_patch_edge: 1e-300, patch_budget: 100, ..opts }).unwrap();
    assert!(tiny.patches.len() <= 100 && tiny.patches.len() >= 20);
    check_mesh(&s, &tiny.patches, tiny.max_patch_edge);
    let e = mesh(&s, &MeshOptions { max_patch_edge: 0.0, ..opts }).unwrap_err();
    assert!(matches!(e, MeshError::BadMaxEdge(_)), "{e}");
    assert!(mesh(&s, &MeshOptions { max_patch_edge: f64::NAN, ..opts }).is_err());
}

fn write_polygons() -> Scene {
    let dir = std::env::temp_dir().join(format!("radiosity-mesh-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut obj = String::from("mtllib m.mtl\nusemtl grey\n");
    // A regular hexagon (radius 1) at z = 0, a regular pentagon at z = 1, a long thin triangle at z = 2, a
    // skewed convex quadrilateral at z = 3 (normals +z).
    let mut nv = 0;
    let mut face = |obj: &mut String, pts: &[(f64, f64)], z: f64| {
        for (x, y) in pts {
            obj.push_str(&format!("v {x} {y} {z}\n"));
        }
        let idx: Vec<String> = (1..=pts.len()).map(|i| (nv + i).to_string()).collect();
        obj.push_str(&format!("f {}\n", idx.join(" ")));
        nv += pts.len();
    };
    let ngon = |n: usize| -> Vec<(f64, f64)> {
        (0..n).map(|i| i as f64 * std::f64::consts::TAU / n as f64).map(|a| (a.cos(), a.sin())).collect()
    };
    face(&mut obj, &ngon(6), 0.0);
    face(&mut obj, &ngon(5), 1.0);
    face(&mut obj, &[(0.0, 0.0), (3.0, 0.0), (0.0, 0.4)], 2.0);
    face(&mut obj, &[(0.0, 0.0), (2.0, 0.2), (1.7, 1.5), (-0.3, 0.9)], 3.0);
    std::fs::write(dir.join("m.obj"), obj).unwrap();
    std::fs::write(dir.join("m.mtl"), "newmtl grey\nKd 0.5 0.5 0.5\n").unwrap();
    let s = Scene::load(dir.join("m.obj")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    s
}

#[test]
fn general_convex_polygons_subdivide_into_convex_pieces() {
    let s = write_polygons();
    for edge in [0.9, 0.3, 0.07] {
        let m = mesh(
            &s,
            &MeshOptions { subdivide: true, max_patch_edge: edge, patch_budget: 100_000, repair: true },
        )
        .unwrap();
        check_mesh(&s, &m.patches, edge);
        // The thin triangle (longest edge 3.0267): either the regular k x k subdivision (k^2 similar triangles)
        // or three gridded quadrilaterals around its centroid, whichever has fewer patches.
        let k = (s.faces[2].polygons[0].max_edge() / edge).ceil() as usize;
        let tris: Vec<&Patch> = m.patches.iter().filter(|p| p.face == 2).collect();
        assert!(tris.len() <= k * k, "edge {edge}: {} > {}", tris.len(), k * k);
        if tris.len() == k * k {
            assert!(tris.iter().all(|p| p.vertices.len() == 3));
        }
        // The hexagon and pentagon (edges 1 and 1.176) become one quadrilateral per vertex, then grids.
        assert!(m.patches.iter().filter(|p| p.face <= 1).all(|p| p.vertices.len() == 4));
    }
}

#[test]
fn refine_splits_selected_patches_and_keeps_area() {
    let s = load("cornell-box");
    let base = mesh(&s, &MeshOptions { repair: false, ..MeshOptions::no_subdivide(&s) }).unwrap().patches;
    // Patch 0 (floor quad, listed twice: split once), 18 (a red-wall triangle).
    let refined = refine(&base, &[18, 0, 0]).unwrap();
    assert_eq!(refined.len(), base.len() + 3 + 3);
    // Children replace their parent in place: the floor's 4 children come first.
    assert!(refined[..4].iter().all(|p| p.face == 0 && p.vertices.len() == 4));
    assert_eq!(refined[4], base[1]);
    check_mesh(&s, &refined, f64::INFINITY);
    // Refining everything twice more still tiles every face exactly.
    let all: Vec<usize> = (0..refined.len()).collect();
    let twice =
        refine(&refine(&refined, &all).unwrap(), &(0..refined.len() * 4).collect::<Vec<_>>()).unwrap();
    assert_eq!(twice.len(), refined.len() * 16);
    check_mesh(&s, &twice, f64::INFINITY);
    // A hexagon gives one quadrilateral per vertex.
    let poly = write_polygons();
    let hex = mesh(&poly, &MeshOptions::no_subdivide(&poly)).unwrap().patches;
    let r = refine(&hex, &[0]).unwrap();
    assert_eq!(r.iter().filter(|p| p.face == 0).count(), 6);
    check_mesh(&poly, &r, f64::INFINITY);
    let e = refine(&base, &[20]).unwrap_err();
    assert_eq!(e, MeshError::NoSuchPatch { index: 20, len: 20 });
}

#[test]
fn adjacency_links_patches_sharing_an_edge_within_a_face() {
    let s = load("facing-squares");
    let m = mesh(
        &s,
        &MeshOptions { subdivide: true, max_patch_edge: 1.0 / 3.0, patch_budget: 100, repair: true },
    )
    .unwrap();
    assert_eq!(m.patches.len(), 18);
    let adj = adjacency(&m.patches);
    // Each square is a 3 x 3 grid (row-major from its first vertex): corners 2, edges 3, centre 4 neighbours.
    for face in 0..2 {
        let base = 9 * face;
        let counts: Vec<usize> = (0..9).map(|i| adj[base + i].len()).collect();
        assert_eq!(counts, [2, 3, 2, 3, 4, 3, 2, 3, 2], "face {face}");
        assert_eq!(adj[base + 4], [base + 1, base + 3, base + 5, base + 7]);
    }
    for (i, n) in adj.iter().enumerate() {
        for &j in n {
            assert!(adj[j].contains(&i), "not symmetric: {i} -> {j}");
            assert_eq!(m.patches[i].face, m.patches[j].face);
        }
    }
    // Split the centre of face 0: its left neighbour (patch 3) now meets two of the children (T-junction).
    let r = refine(&m.patches, &[4]).unwrap();
    let adj = adjacency(&r);
    assert_eq!(adj[3].len(), 4, "{:?}", adj[3]);
    let children = 4usize..8;
    assert_eq!(adj[3].iter().filter(|&&j| children.contains(&j)).count(), 2);
    // Faces that touch (the closed Cornell box's walls meet along edges) are never neighbours.
    let c = load("cornell-box-closed");
    let cm = mesh(&c, &MeshOptions::for_scene(&c)).unwrap();
    let cadj = adjacency(&cm.patches);
    assert!(cadj
        .iter()
        .enumerate()
        .all(|(i, n)| n.iter().all(|&j| cm.patches[j].face == cm.patches[i].face)));
    assert!(
        cadj.iter().all(|n| !n.is_empty()),
        "every Cornell face is subdivided, so every patch has a neighbour"
    );
}

/// A one-face scene holding `polygon`.
fn one_face_scene(polygon: Polygon) -> Scene {
    let face = Face {
        index: 0,
        line: 1,
        gltf: None,
        object: "random".to_owned(),
        material: 0,
        vertices: polygon.vertices.clone(),
        normal: polygon.normal,
        area: polygon.area,
        polygons: vec![polygon],
    };
    Scene {
        path: PathBuf::from("random.obj"),
        faces: vec![face],
        materials: vec![Material {
            name: "grey".to_owned(),
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        }],
        light_groups: Vec::new(),
        meshing: MeshingLimits::default(),
        warnings: Vec::new(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    /// Random convex polygons (3 to 9 vertices on a tilted ellipse, far from the origin) subdivide into convex
    /// pieces inside the face, within the edge limit, with the areas adding up; refining all of them keeps that.
    #[test]
    fn random_convex_polygons_mesh_exactly(
        mut angles in proptest::collection::vec(0.0..std::f64::consts::TAU, 3..10),
        (a, b) in (0.2f64..3.0, 0.2f64..3.0),
        tilt in (-1.0f64..1.0, -1.0f64..1.0, 0.1f64..1.0),
        offset in (-50.0f64..50.0, -50.0f64..50.0, -50.0f64..50.0),
        limit_fraction in 0.05f64..1.5,
    ) {
        angles.sort_by(f64::total_cmp);
        angles.dedup_by(|x, y| (*x - *y).abs() < 0.05);
        prop_assume!(angles.len() >= 3 && (angles[0] + std::f64::consts::TAU - angles[angles.len() - 1]) >= 0.05);
        let n = DVec3::new(tilt.0, tilt.1, tilt.2).normalize();
        let u = n.any_orthonormal_vector();
        let w = n.cross(u);
        let o = DVec3::new(offset.0, offset.1, offset.2);
        let vertices: Vec<DVec3> = angles.iter().map(|t| o + u * (a * t.cos()) + w * (b * t.sin())).collect();
        let polygon = Polygon::new(vertices).expect("a polygon with positive area");
        prop_assume!(polygon.area > 1e-3);
        let s = one_face_scene(polygon);
        let edge = limit_fraction * s.faces[0].polygons[0].diameter();
        let m = mesh(&s, &MeshOptions { subdivide: true, max_patch_edge: edge, patch_budget: 1_000_000, repair: true }).unwrap();
        check_mesh(&s, &m.patches, edge);
        let all: Vec<usize> = (0..m.patches.len()).collect();
        let r = refine(&m.patches, &all).unwrap();
        check_mesh(&s, &r, edge);
    }
}
