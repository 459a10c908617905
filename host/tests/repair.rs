//! Mesh repair: faces cut where other faces meet them (contacts, crossings, T-junctions), hidden pieces culled,
//! areas exact to rounding, `--no-repair` keeping the input, and the published Cornell box against the
//! hand-cut closed variant.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::DVec3;
use radiosity_host::hierarchy::{solve_hierarchical, HierarchyOptions};
use radiosity_host::mesh::{mesh, repair, Meeting, MeshOptions, Repaired};
use radiosity_host::pipeline::{prepare, PrepareOptions};
use radiosity_host::scene::{Polygon, Scene};

static COUNTER: AtomicUsize = AtomicUsize::new(0);

const MTL: &str = "newmtl grey\nKd 0.5 0.5 0.5\n\nnewmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n";

/// Writes `scene.obj` (with `scene.mtl`, and `scene.toml` if given) into a fresh folder.
fn write_scene(obj: &str, toml: Option<&str>) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "radiosity-repair-test-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("scene.mtl"), MTL).unwrap();
    std::fs::write(dir.join("scene.obj"), format!("mtllib scene.mtl\n{obj}")).unwrap();
    if let Some(t) = toml {
        std::fs::write(dir.join("scene.toml"), t).unwrap();
    }
    dir.join("scene.obj")
}

fn load(obj: &str) -> Scene {
    let path = write_scene(obj, None);
    let s = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
    s
}

/// One OBJ face from its vertices (counter-clockwise seen from the front), with material `mtl`.
fn face(mtl: &str, v: &[[f64; 3]]) -> String {
    let mut s = format!("usemtl {mtl}\n");
    for p in v {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    let idx: Vec<String> = (0..v.len()).map(|i| format!("-{}", v.len() - i)).collect();
    s + &format!("f {}\n", idx.join(" "))
}

/// The floor square `[0, size]^2` at y = 0, facing up.
fn floor(size: f64) -> String {
    face("grey", &[[0.0, 0.0, 0.0], [0.0, 0.0, size], [size, 0.0, size], [size, 0.0, 0.0]])
}

/// The faces of the axis-aligned box `lo..hi` with outward normals, bottom (y = lo.y) left out if `bottom` is
/// false, in the order: top, bottom, x-, x+, z-, z+ (bottom omitted when absent).
fn cuboid(lo: [f64; 3], hi: [f64; 3], bottom: bool, mtl: &str) -> String {
    let [x0, y0, z0] = lo;
    let [x1, y1, z1] = hi;
    let mut s = face(mtl, &[[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]]);
    if bottom {
        s += &face(mtl, &[[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]]);
    }
    s += &face(mtl, &[[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]]);
    s += &face(mtl, &[[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]]);
    s += &face(mtl, &[[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]]);
    s += &face(mtl, &[[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]);
    s
}

fn area(polys: &[Polygon]) -> f64 {
    polys.iter().map(|p| p.area).sum()
}

/// Bound on the rounding of a sum of piece areas: every vertex of a piece is a point of an input edge or of a
/// cut line, off by a few interpolations of `eps` times the coordinate scale `c` (`delta = 8 eps c`), which moves
/// a piece's area by at most its perimeter times `delta`; each area is a Newell sum with a relative rounding of a
/// few `eps` per vertex.
fn area_tol(polys: &[Polygon], c: f64) -> f64 {
    let delta = 8.0 * f64::EPSILON * c;
    polys
        .iter()
        .map(|p| {
            let n = p.vertices.len();
            let perimeter: f64 = (0..n).map(|i| p.vertices[i].distance(p.vertices[(i + 1) % n])).sum();
            perimeter * delta + 4.0 * n as f64 * f64::EPSILON * p.area
        })
        .sum()
}

fn coord_scale(s: &Scene) -> f64 {
    s.faces.iter().flat_map(|f| f.vertices.iter()).map(|v| v.abs().max_element()).fold(0.0, f64::max)
}

/// Every repaired polygon is convex, in its face's plane, inside its face, and keeps the face's normal.
fn check_pieces(s: &Scene, r: &Repaired) {
    let tol = 8.0 * f64::EPSILON * coord_scale(s) * 16.0;
    for (f, polys) in r.polygons.iter().enumerate() {
        let face = &s.faces[f];
        for p in polys {
            let parent =
                face.polygons.iter().find(|q| q.normal == p.normal).expect("keeps a polygon's normal");
            let n = p.vertices.len();
            for i in 0..n {
                let (a, b, c) = (p.vertices[i], p.vertices[(i + 1) % n], p.vertices[(i + 2) % n]);
                assert!(
                    (a - parent.centroid).dot(parent.normal).abs() <= tol,
                    "face {f}: piece leaves the plane"
                );
                assert!(
                    (b - a).cross(c - b).dot(p.normal) >= -tol * (b - a).length(),
                    "face {f}: not convex"
                );
                let m = parent.vertices.len();
                for j in 0..m {
                    let (q0, q1) = (parent.vertices[j], parent.vertices[(j + 1) % m]);
                    assert!(
                        (q1 - q0).cross(a - q0).dot(parent.normal) >= -tol * (q1 - q0).length(),
                        "face {f}: piece leaves the face"
                    );
                }
            }
        }
    }
}

/// Whether `x` (in the plane y = 0) lies strictly inside the convex polygon `v` projected on y = 0.
fn inside_xz(v: &[DVec3], x: DVec3) -> bool {
    let n = v.len();
    let cross = |a: DVec3, b: DVec3, p: DVec3| (b.x - a.x) * (p.z - a.z) - (b.z - a.z) * (p.x - a.x);
    let signs: Vec<f64> = (0..n).map(|i| cross(v[i], v[(i + 1) % n], x)).collect();
    signs.iter().all(|&s| s > 0.0) || signs.iter().all(|&s| s < 0.0)
}

#[test]
fn a_box_resting_on_the_floor_cuts_it_along_the_footprint_and_culls_it() {
    let obj = floor(4.0) + &cuboid([1.0, 0.0, 1.5], [2.0, 1.0, 3.0], false, "grey");
    let s = load(&obj);
    let r = repair(&s);
    check_pieces(&s, &r);
    // The floor loses exactly the 1 x 1.5 footprint; the box's faces are as loaded.
    let floor = &r.polygons[0];
    let c = coord_scale(&s);
    assert!((area(floor) - 14.5).abs() <= area_tol(floor, c), "floor area {}", area(floor));
    for f in 1..s.faces.len() {
        assert_eq!(r.polygons[f], s.faces[f].polygons, "face {f} unchanged");
    }
    let footprint = [
        DVec3::new(1.0, 0.0, 1.5),
        DVec3::new(2.0, 0.0, 1.5),
        DVec3::new(2.0, 0.0, 3.0),
        DVec3::new(1.0, 0.0, 3.0),
    ];
    for p in floor {
        assert!(!inside_xz(&footprint, p.centroid), "a kept piece lies under the box: {:?}", p.vertices);
    }
    // The report: the floor alone, touched by the four sides, the footprint culled.
    assert_eq!(r.report.faces.len(), 1);
    let f = &r.report.faces[0];
    assert_eq!((f.face, f.line), (0, s.faces[0].line));
    let sides: Vec<(usize, usize, Meeting)> =
        (2..6).map(|k| (k, s.faces[k].line, Meeting::Contact)).collect();
    assert_eq!(f.met_by, sides);
    assert_eq!(f.lines, 4);
    assert!((f.culled_area - 1.5).abs() <= area_tol(floor, c));
    assert_eq!(f.polygons, floor.len());
    // Merging leaves fewer pieces than the 9 cells of the four lines less the footprint.
    assert!(floor.len() < 8, "{} pieces", floor.len());
    let notes = r.report.notes(Path::new("scene.obj"));
    let text = notes[0].to_string();
    let want = format!(
        "scene.obj:{}: face 0: repaired: touched by faces 2 (line {})",
        s.faces[0].line, s.faces[2].line
    );
    assert!(text.starts_with(&want), "{text}");
    assert!(text.contains("culled 1 piece"), "{text}");
}

#[test]
fn interpenetrating_boxes_lose_what_lies_inside_each_other() {
    // A = [0,2]^3 and B = [1,3]^3, closed, outward normals: each of A's faces x = 2, y = 2, z = 2 has a unit
    // square inside B, and each of B's faces x = 1, y = 1, z = 1 one inside A.
    let obj = cuboid([0.0; 3], [2.0; 3], true, "grey") + &cuboid([1.0; 3], [3.0; 3], true, "grey");
    let s = load(&obj);
    let r = repair(&s);
    check_pieces(&s, &r);
    let c = coord_scale(&s);
    // Face order per box: top (y+), bottom (y-), x-, x+, z-, z+.
    let cut = [0, 3, 5, 6 + 1, 6 + 2, 6 + 4];
    for f in 0..12 {
        let polys = &r.polygons[f];
        if cut.contains(&f) {
            assert!((area(polys) - 3.0).abs() <= area_tol(polys, c), "face {f}: area {}", area(polys));
            // The L-shaped rest is two convex pieces.
            assert_eq!(polys.len(), 2, "face {f}");
        } else {
            assert_eq!(polys, &s.faces[f].polygons, "face {f} unchanged");
        }
    }
    let changed: Vec<usize> = r.report.faces.iter().map(|f| f.face).collect();
    assert_eq!(changed, cut);
    for f in &r.report.faces {
        assert_eq!(f.met_by.len(), 2, "face {}", f.face);
        assert!(f.met_by.iter().all(|m| m.2 == Meeting::Crossing));
        assert_eq!(f.culled_pieces, 1);
        assert!((f.culled_area - 1.0).abs() <= 1e-12);
    }
    assert!((r.report.culled_area() - 6.0).abs() <= 1e-12 * 6.0);
}

#[test]
fn a_wall_ending_inside_the_floor_cuts_it_without_culling() {
    // A T-junction: the partition's bottom edge runs from the floor's edge (z = 0) to its middle (z = 2). The
    // floor is cut along the contact line (the cut runs on to the floor's far edge, so both pieces stay convex)
    // and nothing is culled: both sides of the partition are open.
    let obj =
        floor(4.0) + &face("grey", &[[2.0, 0.0, 0.0], [2.0, 1.0, 0.0], [2.0, 1.0, 2.0], [2.0, 0.0, 2.0]]);
    let s = load(&obj);
    let r = repair(&s);
    check_pieces(&s, &r);
    let floor = &r.polygons[0];
    assert_eq!(floor.len(), 2);
    for p in floor {
        assert!((p.area - 8.0).abs() <= area_tol(floor, coord_scale(&s)), "piece area {}", p.area);
    }
    assert_eq!(r.polygons[1], s.faces[1].polygons);
    let f = &r.report.faces[0];
    assert_eq!((f.lines, f.culled_pieces, f.culled_area), (1, 0, 0.0));
    assert_eq!(f.met_by, vec![(1, s.faces[1].line, Meeting::Contact)]);
}

#[test]
fn faces_that_only_share_edges_or_vertices_are_left_alone() {
    // Coplanar neighbours meeting at a T-vertex (the small square's corner (2, 0, 1) lies on the large one's
    // edge), a wall standing on the floor's border, and a wall touching the floor at one corner only.
    let obj = face("grey", &[[0.0, 0.0, 0.0], [0.0, 0.0, 2.0], [2.0, 0.0, 2.0], [2.0, 0.0, 0.0]])
        + &face("grey", &[[2.0, 0.0, 0.0], [2.0, 0.0, 1.0], [3.0, 0.0, 1.0], [3.0, 0.0, 0.0]])
        + &face("grey", &[[0.0, 0.0, 2.0], [0.0, 1.0, 2.0], [2.0, 1.0, 2.0], [2.0, 0.0, 2.0]])
        + &face("grey", &[[1.0, 0.0, 0.0], [0.5, 1.0, -0.5], [1.5, 1.0, -0.5]]);
    let s = load(&obj);
    let r = repair(&s);
    assert!(r.report.faces.is_empty(), "{:?}", r.report.faces);
    for (f, polys) in r.polygons.iter().enumerate() {
        assert_eq!(polys, &s.faces[f].polygons);
    }
}

#[test]
fn no_repair_keeps_the_input() {
    let obj = floor(4.0) + &cuboid([1.0, 0.0, 1.0], [2.0, 1.0, 2.0], false, "grey");
    let s = load(&obj);
    let raw = mesh(&s, &MeshOptions { repair: false, ..MeshOptions::no_subdivide(&s) }).unwrap();
    assert!(raw.repair.is_none());
    assert_eq!(raw.patches.len(), s.faces.len());
    for (p, f) in raw.patches.iter().zip(&s.faces) {
        assert_eq!((p.face, &p.vertices, p.area), (f.index, &f.vertices, f.area));
    }
    let repaired = mesh(&s, &MeshOptions::no_subdivide(&s)).unwrap();
    assert!(repaired.patches.len() > raw.patches.len());
    assert_eq!(repaired.repair.as_ref().map(|r| r.faces.len()), Some(1));
    // The pipeline's option and the scene's TOML both turn it off.
    let path = write_scene(&obj, None);
    let options = PrepareOptions { repair: false, ..PrepareOptions::quiet(true, 4, 4) };
    let p = prepare(&path, &options).unwrap();
    assert!(p.repair.is_none());
    assert_eq!(p.patches, raw.patches);
    let p = prepare(&path, &PrepareOptions::quiet(true, 4, 4)).unwrap();
    assert_eq!(p.patches, repaired.patches);
    let toml = write_scene(&obj, Some("[meshing]\nrepair = false\n"));
    let p = prepare(&toml, &PrepareOptions::quiet(true, 4, 4)).unwrap();
    assert!(p.repair.is_none());
    assert_eq!(p.patches, raw.patches);
    for dir in [path, toml] {
        std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
    }
}

fn cornell(name: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../scenes/{name}.obj"));
    Scene::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Shoelace area of a polygon's projection on y = 0.
fn footprint_area(v: &[DVec3]) -> f64 {
    let n = v.len();
    0.5 * (0..n).map(|i| v[i].z * v[(i + 1) % n].x - v[i].x * v[(i + 1) % n].z).sum::<f64>().abs()
}

#[test]
fn published_cornell_box_floor_loses_the_block_footprints() {
    let s = cornell("cornell-box");
    let r = repair(&s);
    check_pieces(&s, &r);
    // Faces 0 floor, 8 short block top, 13 tall block top (scenes/cornell-box.obj).
    let (short, tall) = (&s.faces[8].vertices, &s.faces[13].vertices);
    let expected = s.faces[0].area - footprint_area(short) - footprint_area(tall);
    let floor = &r.polygons[0];
    let c = coord_scale(&s);
    assert!(
        (area(floor) - expected).abs() <= area_tol(floor, c),
        "floor {} vs floor minus footprints {expected}",
        area(floor)
    );
    for p in floor {
        assert!(!inside_xz(short, p.centroid) && !inside_xz(tall, p.centroid), "piece under a block");
    }
    // Only the floor changes: the blocks stand on it, nothing else meets a face inside it.
    assert_eq!(r.report.faces.iter().map(|f| f.face).collect::<Vec<_>>(), vec![0]);
    let f = &r.report.faces[0];
    let sides: Vec<usize> = f.met_by.iter().map(|m| m.0).collect();
    assert_eq!(sides, (9..13).chain(14..18).collect::<Vec<_>>());
    assert!(f.met_by.iter().all(|m| m.2 == Meeting::Contact));
    // The hand-cut closed variant's floor pieces (faces 0..16), written with 9 decimals: each coordinate is off by
    // up to 5e-10, moving a piece's area by up to its perimeter times that (times sqrt 2 for two coordinates).
    let closed = cornell("cornell-box-closed");
    let pieces: Vec<Polygon> = closed.faces[..17].iter().flat_map(|f| f.polygons.clone()).collect();
    assert!(pieces.iter().all(|p| p.normal.y > 0.999), "closed variant: faces 0..16 are the floor");
    let written = area_tol(&pieces, c)
        + pieces
            .iter()
            .map(|p| {
                let n = p.vertices.len();
                (0..n).map(|i| p.vertices[i].distance(p.vertices[(i + 1) % n])).sum::<f64>()
            })
            .sum::<f64>()
            * 5e-10
            * std::f64::consts::SQRT_2;
    assert!(
        (area(floor) - area(&pieces)).abs() <= area_tol(floor, c) + written,
        "repaired floor {} vs hand-cut floor {}",
        area(floor),
        area(&pieces)
    );
    // Repairing the hand-cut variant changes nothing.
    assert!(repair(&closed).report.faces.is_empty());
}

#[test]
fn the_hierarchy_takes_several_roots_per_face() {
    // A lit box (a light in the ceiling of a closed room, inward normals) with a block resting on its floor: the
    // floor is repaired into pieces, each a root of the hierarchy, and its leaves add up to the floor less the
    // footprint, all with face 0.
    let room = |lo: f64, hi: f64| {
        let mut s = String::new();
        // Inward normals: the floor faces up, the ceiling down, the walls inward.
        s += &face("grey", &[[lo, lo, lo], [lo, lo, hi], [hi, lo, hi], [hi, lo, lo]]);
        s += &face("grey", &[[lo, hi, lo], [hi, hi, lo], [hi, hi, hi], [lo, hi, hi]]);
        s += &face("grey", &[[lo, lo, lo], [lo, hi, lo], [lo, hi, hi], [lo, lo, hi]]);
        s += &face("grey", &[[hi, lo, lo], [hi, lo, hi], [hi, hi, hi], [hi, hi, lo]]);
        s += &face("grey", &[[lo, lo, lo], [hi, lo, lo], [hi, hi, lo], [lo, hi, lo]]);
        s += &face("grey", &[[lo, lo, hi], [lo, hi, hi], [hi, hi, hi], [hi, lo, hi]]);
        s
    };
    let lamp = face("lamp", &[[1.5, 3.999, 1.5], [2.5, 3.999, 1.5], [2.5, 3.999, 2.5], [1.5, 3.999, 2.5]]);
    let obj = room(0.0, 4.0) + &lamp + &cuboid([1.0, 0.0, 1.0], [2.0, 1.0, 2.5], false, "grey");
    let s = load(&obj);
    let r = repair(&s);
    assert_eq!(r.report.faces.iter().map(|f| f.face).collect::<Vec<_>>(), vec![0]);
    assert!(r.polygons[0].len() > 1);
    let options = HierarchyOptions { epsilon: 0.3, ..HierarchyOptions::default() };
    let sol = solve_hierarchical(&s, &options).unwrap();
    assert_eq!(sol.stats.polygons, r.polygons.iter().map(Vec::len).sum::<usize>());
    let floor: Vec<Polygon> = r.polygons[0].clone();
    let leaves: Vec<Polygon> = sol
        .leaves
        .iter()
        .filter(|p| p.face == 0)
        .map(|p| Polygon::with_normal(p.vertices.clone(), p.normal).unwrap())
        .collect();
    // The pieces' rounding, and the leaves' (each cut from a piece the same way).
    let c = coord_scale(&s);
    let allowed = area_tol(&floor, c) + area_tol(&leaves, c);
    assert!((area(&leaves) - 14.5).abs() <= allowed, "floor leaves {}", area(&leaves));
    assert!(sol.b.iter().all(|b| b.is_finite()));
    // The claim is finite, and the floor is lit.
    assert!(sol.error_bound.is_some());
    assert!(sol.leaves.iter().zip(&sol.b).any(|(p, b)| p.face == 0 && b.max_element() > 0.0));
}
