//! Light maps: per-face textures of the smoothed radiosity, packed into one atlas, the way game engines consume
//! baked lighting.
//!
//! **Charts.** Every OBJ face (every distinct [`Patch::face`]) is drawn in one chart, a rectangle of texels. Faces
//! of one material whose normals agree and that share a patch vertex are joined into one chart, transitively (the
//! Cornell box's ceiling is four faces around the light: one chart), so there is no seam between them at all; any
//! other two faces meet at a crease or a material boundary, where the lighting may jump anyway. A chart's frame:
//! its normal `n` (area-weighted over its patches), a `u` axis along a side of the smallest rectangle around the
//! chart (the first edge of its first patch when that rectangle is aligned with it), `v = u x n` (so that, seen
//! from the front with `u` to the right, `v` points down, like image rows), and an origin at the lower corner of
//! the chart's bounding rectangle in that frame. Texel `(i, j)` of the chart (column `i`, row `j`) has its centre
//! at `origin + (i + 0.5) * texel_size * u + (j + 0.5) * texel_size * v` and holds the smooth shader's value there
//! ([`SmoothShader::shade`] on the chart's patch containing the point; texels in the padding border, between
//! patches, in a hole (the ceiling's light) or outside a non-rectangular face take the patch of the nearest covered
//! texel, found by a flood fill over the texel grid (dilation), and the shader moves the point onto that patch's
//! boundary). Each rectangle is surrounded by `padding` texels filled the same way.
//!
//! **Smoothness and gutters.** The smooth shader interpolates vertex values fitted over all compatible patches
//! around a vertex (same material, normals within the crease angle), so the field is continuous across the edges
//! inside a chart; each chart samples that one field. A bilinear filter at an atlas point `(ax, ay)` reads the
//! four texels around `(ax - 0.5, ay - 0.5)` (see [`Footprint`] and [`LightMap::bilinear`]), so at a point of a
//! face it reaches at most one texel beyond the chart's rectangle: a padding of at least 1 (the default is 2)
//! keeps every read inside the chart's own padded rectangle, where every texel is written with the field at (or
//! moved onto) the chart. Mip-mapped sampling would reach further: a sampler for this atlas should not use mip
//! maps (the `.glb` export's does not).
//!
//! Packing is a shelf packer (rectangles sorted by decreasing height, placed left to right on shelves as wide as
//! the square root of the total padded area). The atlas is written as OpenEXR (linear radiosity in W/m^2, RGB
//! 32-bit float; see [`super::hdr`]), linear Radiance `.hdr` (the same values in RGBE, 8-bit mantissas), a
//! tone-mapped PNG (see [`super::tonemap`]) and a JSON map (see [`LightMap::to_json`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};
use serde::Serialize;

use super::hdr::{write_exr, write_hdr, LinearImage};
use super::shading::SmoothShader;
use super::{write_file, write_png, PictureError, ToneMap};
use crate::patch::Patch;
use crate::rgb::{luminance, Rgb};

/// Options for [`bake_light_map`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightMapOptions {
    /// Texel edge length in scene units; `None` chooses it so the largest chart is `max_face_texels` texels across.
    pub texel_size: Option<f64>,
    /// Texels across the largest chart (a face, or coplanar faces joined) when `texel_size` is `None`.
    pub max_face_texels: u32,
    /// Border texels around each face rectangle; at least 1 (see the module docs on gutters).
    pub padding: u32,
}

impl Default for LightMapOptions {
    fn default() -> Self {
        LightMapOptions { texel_size: None, max_face_texels: 64, padding: 2 }
    }
}

/// Largest rectangle side, in texels, a face may get (keeps a tiny `texel_size` from asking for gigabytes); the
/// whole atlas is held to [`crate::limits::MAX_IMAGE_PIXELS`] like every picture.
pub const MAX_FACE_SIDE: u32 = 4096;

/// Where one face lives in the atlas, and how to get from a point on the face to its texel.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaceRect {
    /// OBJ face index.
    pub face: usize,
    /// The chart the face is drawn in: coplanar faces of one material that share a vertex share a chart (and so
    /// the same rectangle, frame and texels), so the light map is continuous across the edges between them.
    pub chart: usize,
    /// Left column of the face's texels in the atlas (padding excluded).
    pub x: u32,
    /// Top row of the face's texels in the atlas (padding excluded).
    pub y: u32,
    /// Width in texels (padding excluded).
    pub width: u32,
    /// Height in texels (padding excluded).
    pub height: u32,
    /// Scene-space point at the outer corner of texel `(x, y)`.
    pub origin: DVec3,
    /// Unit vector along increasing atlas columns.
    pub u_axis: DVec3,
    /// Unit vector along increasing atlas rows.
    pub v_axis: DVec3,
    /// Face normal.
    pub normal: DVec3,
    /// Texel edge length in scene units.
    pub texel_size: f64,
    /// Number of patches the face was meshed into (the face's own, not its chart's).
    pub patches: usize,
}

impl FaceRect {
    /// Atlas texel coordinates (continuous: texel `(i, j)` spans `[i, i + 1) x [j, j + 1)`) of a point on the face.
    #[must_use]
    pub fn atlas_coords(&self, point: DVec3) -> (f64, f64) {
        let d = point - self.origin;
        (
            f64::from(self.x) + d.dot(self.u_axis) / self.texel_size,
            f64::from(self.y) + d.dot(self.v_axis) / self.texel_size,
        )
    }
}

impl FaceRect {
    /// The rectangle with its padding: `(left, top, width, height)` in atlas texels. Every texel in it is
    /// written by [`bake_light_map`]; a bilinear filter at any point of the face reads only texels in it.
    #[must_use]
    pub fn padded(&self, padding: u32) -> (u32, u32, u32, u32) {
        (self.x - padding, self.y - padding, self.width + 2 * padding, self.height + 2 * padding)
    }
}

/// The four texels a bilinear filter reads at a continuous atlas point, with their weights (they sum to 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Texel `(column, row)` of each of the four reads; indices may be -1 or the atlas size at its border.
    pub texels: [(i64, i64); 4],
    /// The weight of each read.
    pub weights: [f64; 4],
}

impl Footprint {
    /// The footprint at atlas point `(ax, ay)` (texel `(i, j)` spans `[i, i + 1) x [j, j + 1)`; its centre is at
    /// `(i + 0.5, j + 0.5)`), as the GPU's linear (non-mip-mapped) filter computes it.
    #[must_use]
    pub fn at(ax: f64, ay: f64) -> Self {
        let (sx, sy) = (ax - 0.5, ay - 0.5);
        let (x0, y0) = (sx.floor(), sy.floor());
        let (fx, fy) = (sx - x0, sy - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        Footprint {
            texels: [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)],
            weights: [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy],
        }
    }
}

/// A baked light-map atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct LightMap {
    /// The atlas, linear radiosity (W/m^2) per texel; unused texels are black.
    pub atlas: LinearImage,
    /// One rectangle per face, in face order (faces of one chart have the same rectangle).
    pub rects: Vec<FaceRect>,
    /// Border texels around each rectangle.
    pub padding: u32,
    /// Texel edge length in scene units.
    pub texel_size: f64,
}

/// Bakes the light map of `patches` with per-patch `radiosity`, shaded by `shader` (built from the same patches).
///
/// # Errors
/// [`PictureError::Invalid`] if the shader was built for a different number of patches, `radiosity` has the wrong
/// length, some face index below the largest has no patch (every face must be mapped), the texel size is not
/// positive, or a face would need more than [`MAX_FACE_SIDE`] texels across; [`PictureError::NonFinite`] for a
/// NaN or infinite radiosity (naming the patch).
pub fn bake_light_map(
    patches: &[Patch],
    shader: &SmoothShader,
    radiosity: &[Rgb],
    options: &LightMapOptions,
) -> Result<LightMap, PictureError> {
    if shader.patch_count() != patches.len() || radiosity.len() != patches.len() {
        return Err(PictureError::invalid(
            "light map input",
            format!(
                "{} patches, shader built for {}, {} radiosity values",
                patches.len(),
                shader.patch_count(),
                radiosity.len()
            ),
        ));
    }
    if patches.is_empty() {
        return Err(PictureError::invalid("light map input", "no patches"));
    }
    let mut by_face: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (i, p) in patches.iter().enumerate() {
        by_face.entry(p.face).or_default().push(i);
    }
    for (expected, &face) in by_face.keys().enumerate() {
        if face != expected {
            return Err(PictureError::invalid(
                "light map input",
                format!("face {expected} has no patch, so it cannot be mapped (faces present: up to {face})"),
            ));
        }
    }

    // Charts: faces of one material and one plane that share a vertex are joined (union-find), so the light map
    // has no seam where they meet.
    let chart_of = charts(patches, &by_face, shader.tolerance());
    let mut by_chart: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (&face, members) in &by_face {
        by_chart.entry(chart_of[face]).or_default().extend(members);
    }

    // Chart frames and extents.
    struct Layout {
        faces: Vec<usize>,
        members: Vec<usize>,
        origin: DVec3,
        u: DVec3,
        v: DVec3,
        normal: DVec3,
        extent: (f64, f64),
    }
    let mut layouts = Vec::with_capacity(by_chart.len());
    for (&chart, members) in &by_chart {
        let normal =
            members.iter().map(|&i| patches[i].normal * patches[i].area).sum::<DVec3>().normalize_or_zero();
        let first = &patches[members[0]];
        let normal = if normal == DVec3::ZERO { first.normal } else { normal };
        let edge = first.vertices[1] - first.vertices[0];
        let u0 = (edge - normal * edge.dot(normal)).normalize_or(normal.any_orthonormal_vector());
        let v0 = u0.cross(normal);
        let base = first.vertices[0];
        let points: Vec<DVec2> = members
            .iter()
            .flat_map(|&i| &patches[i].vertices)
            .map(|&p| DVec2::new((p - base).dot(u0), (p - base).dot(v0)))
            .collect();
        let d = smallest_rectangle_direction(&points);
        let u = u0 * d.x + v0 * d.y;
        let v = u.cross(normal);
        let (mut lo, mut hi) = ((f64::INFINITY, f64::INFINITY), (f64::NEG_INFINITY, f64::NEG_INFINITY));
        for &i in members {
            for &p in &patches[i].vertices {
                let d = p - base;
                let (a, b) = (d.dot(u), d.dot(v));
                lo = (lo.0.min(a), lo.1.min(b));
                hi = (hi.0.max(a), hi.1.max(b));
            }
        }
        layouts.push(Layout {
            faces: by_face.keys().copied().filter(|&f| chart_of[f] == chart).collect(),
            members: members.clone(),
            origin: base + u * lo.0 + v * lo.1,
            u,
            v,
            normal,
            extent: (hi.0 - lo.0, hi.1 - lo.1),
        });
    }
    let texel_size = match options.texel_size {
        Some(t) => t,
        None => {
            let largest = layouts.iter().map(|l| l.extent.0.max(l.extent.1)).fold(0.0, f64::max);
            largest / f64::from(options.max_face_texels.max(1))
        }
    };
    if !(texel_size.is_finite() && texel_size > 0.0) {
        return Err(PictureError::invalid("light map texel size", format!("{texel_size} is not positive")));
    }
    let pad = options.padding;
    if pad == 0 {
        return Err(PictureError::invalid(
            "light map padding",
            "0 texels: bilinear filtering at a face's edge would read the neighbouring chart (at least 1)",
        ));
    }
    let mut sizes = Vec::with_capacity(layouts.len());
    for l in &layouts {
        // A side of exactly n texels stays n when rounding lands it a hair above (the padding covers the hair).
        let side = |e: f64| (e / texel_size * (1.0 - 1e-12)).ceil().max(1.0);
        let (w, h) = (side(l.extent.0), side(l.extent.1));
        if w > f64::from(MAX_FACE_SIDE) || h > f64::from(MAX_FACE_SIDE) {
            return Err(PictureError::invalid(
                "light map texel size",
                format!(
                    "face {} would be {w}x{h} texels (limit {MAX_FACE_SIDE}); use a larger texel",
                    l.faces[0]
                ),
            ));
        }
        sizes.push((w as u32, h as u32));
    }

    // Shelf packing of the padded rectangles.
    let padded: Vec<(u32, u32)> = sizes.iter().map(|&(w, h)| (w + 2 * pad, h + 2 * pad)).collect();
    let area: f64 = padded.iter().map(|&(w, h)| f64::from(w) * f64::from(h)).sum();
    let atlas_width = padded.iter().map(|r| r.0).max().unwrap_or(1).max(area.sqrt().ceil() as u32);
    let mut order: Vec<usize> = (0..padded.len()).collect();
    order.sort_by(|&a, &b| padded[b].1.cmp(&padded[a].1).then(padded[b].0.cmp(&padded[a].0)).then(a.cmp(&b)));
    let mut place = vec![(0u32, 0u32); padded.len()];
    let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
    for &k in &order {
        let (w, h) = padded[k];
        if x + w > atlas_width {
            y += shelf;
            x = 0;
            shelf = 0;
        }
        place[k] = (x, y);
        x += w;
        shelf = shelf.max(h);
    }
    let atlas_height = y + shelf;
    // The atlas is a picture: the same limit as every other ([`crate::limits::check_image_size`]).
    crate::limits::check_image_size("light map atlas", atlas_width, atlas_height).map_err(|e| {
        PictureError::invalid(
            "light map texel size",
            format!("{atlas_width}x{atlas_height} texels: {}; use a larger texel", e.problem),
        )
    })?;

    let mut atlas = LinearImage::new(atlas_width, atlas_height);
    let mut rects = Vec::with_capacity(layouts.len());
    for (k, l) in layouts.iter().enumerate() {
        let (w, h) = sizes[k];
        let (px, py) = place[k];
        let (pw, ph) = (w + 2 * pad, h + 2 * pad);
        let centre = |i: u32, j: u32| {
            let (fi, fj) = (f64::from(i) - f64::from(pad) + 0.5, f64::from(j) - f64::from(pad) + 0.5);
            l.origin + l.u * (fi * texel_size) + l.v * (fj * texel_size)
        };
        // Owner of each texel centre: the patch containing it, found by visiting only the texels within each
        // patch's bounding box (so the cost is about the texel count, not texels x patches).
        let mut owner: Vec<Option<usize>> = vec![None; pw as usize * ph as usize];
        for &m in &l.members {
            let (mut lo, mut hi) = ((f64::INFINITY, f64::INFINITY), (f64::NEG_INFINITY, f64::NEG_INFINITY));
            for &p in &patches[m].vertices {
                let d = p - l.origin;
                let (a, b) =
                    (d.dot(l.u) / texel_size + f64::from(pad), d.dot(l.v) / texel_size + f64::from(pad));
                lo = (lo.0.min(a), lo.1.min(b));
                hi = (hi.0.max(a), hi.1.max(b));
            }
            let range = |a: f64, b: f64, n: u32| {
                let first = (a - 0.5).floor().max(0.0) as u32;
                let last = ((b - 0.5).ceil().max(0.0) as u32).min(n - 1);
                first..=last
            };
            for j in range(lo.1, hi.1, ph) {
                for i in range(lo.0, hi.0, pw) {
                    let slot = &mut owner[j as usize * pw as usize + i as usize];
                    if slot.is_none() && shader.distance_in_plane(m, centre(i, j)) == 0.0 {
                        *slot = Some(m);
                    }
                }
            }
        }
        // Texels outside every patch (the padding border, gaps, the uncovered part of a non-rectangular face) take
        // the patch of the nearest owned texel, by a breadth-first flood over the texel grid from the owned ones
        // (dilation); `shade` then moves their centre onto that patch's boundary.
        let mut queue: std::collections::VecDeque<usize> =
            (0..owner.len()).filter(|&t| owner[t].is_some()).collect();
        if queue.is_empty() {
            // No texel centre falls inside any patch (a face thinner than a texel): nearest patch per texel.
            for (t, slot) in owner.iter_mut().enumerate() {
                let point = centre(t as u32 % pw, t as u32 / pw);
                *slot = l
                    .members
                    .iter()
                    .map(|&m| (shader.distance_in_plane(m, point), m))
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .map(|(_, m)| m);
            }
        }
        while let Some(t) = queue.pop_front() {
            let (i, j) = (t as u32 % pw, t as u32 / pw);
            let neighbours = [(i.wrapping_sub(1), j), (i + 1, j), (i, j.wrapping_sub(1)), (i, j + 1)];
            for (ni, nj) in neighbours {
                if ni < pw && nj < ph {
                    let n = nj as usize * pw as usize + ni as usize;
                    if owner[n].is_none() {
                        owner[n] = owner[t];
                        queue.push_back(n);
                    }
                }
            }
        }
        for j in 0..ph {
            for i in 0..pw {
                let patch = owner[j as usize * pw as usize + i as usize].unwrap_or(l.members[0]);
                let value = shader.shade(radiosity, patch, centre(i, j))?;
                let index = (py + j) as usize * atlas_width as usize + (px + i) as usize;
                atlas.pixels[index] = value.as_vec3().to_array();
            }
        }
        for &face in &l.faces {
            rects.push(FaceRect {
                face,
                chart: k,
                x: px + pad,
                y: py + pad,
                width: w,
                height: h,
                origin: l.origin,
                u_axis: l.u,
                v_axis: l.v,
                normal: l.normal,
                texel_size,
                patches: by_face[&face].len(),
            });
        }
    }
    rects.sort_by_key(|r| r.face);
    Ok(LightMap { atlas, rects, padding: pad, texel_size })
}

/// The direction of the side of the smallest-area rectangle around `points` (a unit vector; `(1, 0)` when the
/// points are degenerate). The smallest enclosing rectangle has a side along an edge of the convex hull (H.
/// Freeman and R. Shapira, "Determining the minimum-area encasing rectangle for an arbitrary closed curve", CACM
/// 18(7), 1975), so each hull edge is tried; ties keep the first, so an axis-aligned rectangle keeps `(1, 0)`.
fn smallest_rectangle_direction(points: &[DVec2]) -> DVec2 {
    // Andrew's monotone chain.
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return DVec2::X;
    }
    let mut hull: Vec<DVec2> = Vec::with_capacity(2 * sorted.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &DVec2>> =
            if pass == 0 { Box::new(sorted.iter()) } else { Box::new(sorted.iter().rev()) };
        for &p in iter {
            while hull.len() >= start + 2 {
                let (a, b) = (hull[hull.len() - 2], hull[hull.len() - 1]);
                if (b - a).perp_dot(p - a) <= 0.0 {
                    hull.pop();
                } else {
                    break;
                }
            }
            hull.push(p);
        }
        hull.pop();
    }
    let area = |d: DVec2| {
        let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
        for &p in &hull {
            let q = DVec2::new(p.dot(d), p.perp_dot(d));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        (hi - lo).x * (hi - lo).y
    };
    // Relative slack so that rounding never trades the first direction for an equal one.
    let mut best = (DVec2::X, area(DVec2::X) * (1.0 - 1e-9));
    for k in 0..hull.len() {
        let Some(d) = (hull[(k + 1) % hull.len()] - hull[k]).try_normalize() else { continue };
        let a = area(d);
        if a < best.1 {
            best = (d, a * (1.0 - 1e-9));
        }
    }
    best.0
}

/// The chart of every face (indexed by face): faces of one material whose normals agree to 1e-9 and that share a
/// patch vertex (within `tolerance`) are in one chart, transitively; charts are numbered by their smallest face.
fn charts(patches: &[Patch], by_face: &BTreeMap<usize, Vec<usize>>, tolerance: f64) -> Vec<usize> {
    let n = by_face.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut f: usize) -> usize {
        while parent[f] != f {
            parent[f] = parent[parent[f]];
            f = parent[f];
        }
        f
    }
    let normal: Vec<DVec3> = by_face
        .values()
        .map(|m| m.iter().map(|&i| patches[i].normal * patches[i].area).sum::<DVec3>().normalize_or_zero())
        .collect();
    // Vertices on a grid of cells 4 tolerances wide; two vertices within the tolerance are in one cell or in
    // neighbouring ones.
    let cell = 4.0 * tolerance.max(f64::MIN_POSITIVE);
    let key = |v: DVec3| {
        let k = (v / cell).floor();
        (k.x as i64, k.y as i64, k.z as i64)
    };
    let mut grid: std::collections::HashMap<(i64, i64, i64), Vec<(DVec3, usize)>> = Default::default();
    for (&face, members) in by_face {
        for &i in members {
            for &v in &patches[i].vertices {
                grid.entry(key(v)).or_default().push((v, face));
            }
        }
    }
    for (&face, members) in by_face {
        let material = patches[members[0]].material;
        for &i in members {
            for &v in &patches[i].vertices {
                let (x, y, z) = key(v);
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            let Some(list) = grid.get(&(x + dx, y + dy, z + dz)) else { continue };
                            for &(w, other) in list {
                                let joinable = other != face
                                    && (w - v).length() <= tolerance
                                    && patches[by_face[&other][0]].material == material
                                    && normal[face].dot(normal[other]) >= 1.0 - 1e-9;
                                if joinable {
                                    let (a, b) = (root(&mut parent, face), root(&mut parent, other));
                                    parent[a.max(b)] = a.min(b);
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    // Number the charts 0.. in order of their smallest face.
    let mut number = vec![usize::MAX; n];
    let mut next = 0;
    (0..n)
        .map(|f| {
            let r = root(&mut parent, f);
            if number[r] == usize::MAX {
                number[r] = next;
                next += 1;
            }
            number[r]
        })
        .collect()
}

impl LightMap {
    /// The JSON map: atlas size and files, conventions, and one entry per face (see [`FaceRect`]).
    #[must_use]
    pub fn to_json(&self, exr_file: &str, hdr_file: &str, png_file: &str) -> serde_json::Value {
        serde_json::json!({
            "format": "radiosity-lightmap/1",
            "atlas": {
                "width": self.atlas.width,
                "height": self.atlas.height,
                "exr": exr_file,
                "hdr": hdr_file,
                "png": png_file,
            },
            "units": "the .exr (RGB 32-bit float) and the .hdr (RGBE) hold linear radiosity in W/m^2 (scene units); \
                the .png is tone mapped and sRGB encoded",
            "texel_size": self.texel_size,
            "padding": self.padding,
            "convention": "texel (x + i, y + j) of a face has its centre at origin + (i + 0.5) * texel_size * u_axis \
                + (j + 0.5) * texel_size * v_axis; rows count downward from the top of the atlas; the normalized UV \
                of a face point p is ((x + dot(p - origin, u_axis) / texel_size) / atlas.width, \
                (y + dot(p - origin, v_axis) / texel_size) / atlas.height)",
            "faces": self.rects,
        })
    }

    /// Luminances of the texels inside chart rectangles (padding excluded; each chart once), for choosing an
    /// exposure.
    #[must_use]
    pub fn face_luminances(&self) -> Vec<f64> {
        let w = self.atlas.width as usize;
        let mut out = Vec::new();
        let mut seen = std::collections::BTreeSet::new();
        for r in self.rects.iter().filter(|r| seen.insert(r.chart)) {
            for y in r.y..r.y + r.height {
                for x in r.x..r.x + r.width {
                    out.push(luminance(Rgb::from_array(
                        self.atlas.pixels[y as usize * w + x as usize].map(f64::from),
                    )));
                }
            }
        }
        out
    }

    /// The bilinearly filtered atlas at continuous atlas point `(ax, ay)` (see [`Footprint::at`]), with reads
    /// outside the atlas clamped to its border (the GPU's clamp-to-edge).
    #[must_use]
    pub fn bilinear(&self, ax: f64, ay: f64) -> Rgb {
        let f = Footprint::at(ax, ay);
        let (w, h) = (i64::from(self.atlas.width), i64::from(self.atlas.height));
        let mut out = Rgb::ZERO;
        for (&(x, y), &weight) in f.texels.iter().zip(&f.weights) {
            let (x, y) = (x.clamp(0, w - 1) as usize, y.clamp(0, h - 1) as usize);
            out += weight * Rgb::from_array(self.atlas.pixels[y * w as usize + x].map(f64::from));
        }
        out
    }

    /// Writes `<stem>.exr`, `<stem>.hdr`, `<stem>.png` and `<stem>.json` and returns their paths in that order.
    /// The PNG uses `tone`, or when `None` a [`ToneMap::from_percentile`] exposure over the face texels with the
    /// default percentile and white.
    ///
    /// # Errors
    /// [`PictureError::Io`] / [`PictureError::Png`] / [`PictureError::Format`] if a file cannot be written.
    pub fn write(&self, stem: &Path, tone: Option<ToneMap>) -> Result<[PathBuf; 4], PictureError> {
        let exr = stem.with_extension("exr");
        let hdr = stem.with_extension("hdr");
        let png = stem.with_extension("png");
        let json = stem.with_extension("json");
        let tone = match tone {
            Some(t) => t,
            None => ToneMap::from_percentile(
                &self.face_luminances(),
                ToneMap::DEFAULT_PERCENTILE,
                ToneMap::DEFAULT_WHITE,
            )?,
        };
        let linear: Vec<Rgb> = self.atlas.pixels.iter().map(|p| Rgb::from_array(p.map(f64::from))).collect();
        write_exr(&exr, &self.atlas)?;
        write_hdr(&hdr, &self.atlas)?;
        write_png(&png, &tone.map_image(&linear, self.atlas.width, self.atlas.height)?)?;
        let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let text = serde_json::to_string_pretty(&self.to_json(&name(&exr), &name(&hdr), &name(&png)))
            .map_err(|e| PictureError::invalid("light map JSON", e.to_string()))?;
        write_file(&json, text.as_bytes())?;
        Ok([exr, hdr, png, json])
    }
}
