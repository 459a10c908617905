//! glTF 2.0 scenes (`.gltf` with its buffers and images, or `.glb`), read with the `gltf` crate and turned into
//! the same validated [`Face`]s and [`Material`]s as an OBJ file (the user reference is `docs/scene-format.md`).
//!
//! # Geometry
//! The default scene (or the first, if the file names none) is walked depth first: root nodes in the scene's
//! order, children in the node's order. Each node's transform (a matrix, or translation, rotation and scale) is
//! composed in f64 with its parents', and every primitive of the node's mesh is placed with it: positions are
//! f32 in the file, transformed in f64. Primitives of mode `TRIANGLES` (indexed or not), `TRIANGLE_STRIP` and
//! `TRIANGLE_FAN` are surfaces (strips and fans are expanded to triangles with the winding the glTF spec gives;
//! in a strip, triangles with a repeated index are the usual way to join strips and are skipped); points and
//! lines are refused. A matrix whose last row is not (0, 0, 0, 1) is refused (glTF transforms are affine);
//! skins and morph targets are ignored with a warning (the geometry is static, placed as the positions and the
//! node transforms say). A transform with a negative determinant mirrors the mesh, which the spec says turns its
//! triangles clockwise: their vertex order is reversed, so every face keeps facing where the file says.
//!
//! Every triangle is checked as an OBJ face is (non-finite, coincident or collinear vertices), then consecutive
//! triangles of a primitive that form a fan (each starts at the fan's first vertex index and at its last one)
//! are joined into one face while the union stays one planar convex polygon within
//! [`PLANAR_TOLERANCE`](super::PLANAR_TOLERANCE): this
//! is how exporters write a polygon, and it gives the mesher the modeller's polygon (a quad subdivides into
//! quads) instead of two slivers. Faces are numbered in that order; [`Face::gltf`] says where each came from, and
//! every error names the node, mesh, primitive and triangle.
//!
//! # Materials
//! Every material of the file is a [`Material`], in file order, named by its `name` (`material_N` if it has
//! none; two materials with one name are an error, as in MTL). Reflectance is the RGB of
//! `pbrMetallicRoughness.baseColorFactor`, times the mean of the base-colour texture if there is one. Emission is
//! `emissiveFactor` times `KHR_materials_emissive_strength.emissiveStrength` (default 1), times the mean of the
//! emissive texture if there is one, read as radiant exitance in W/m^2: exactly what MTL `Ke` means here, so a
//! glTF and an OBJ scene with the same numbers give the same radiosity. A texture's mean is over all its texels,
//! decoded from sRGB to linear as the spec says both textures are (alpha and texture coordinates play no part);
//! an image that cannot be decoded is an error naming the material, texture and image. A primitive without a
//! material is refused (glTF's default material has reflectance 1, which no diffuse surface has). Materials
//! that faces use and that are metallic (`metallicFactor > 0`, glTF's default is 1) or double-sided get a
//! warning: this tool treats every surface as diffuse and one-sided.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3};
use gltf::mesh::Mode;
use gltf::Semantic;

use super::error::{SceneError, SceneWarning};
use super::face::{build_face, Face, GltfPlace};
use super::material::Material;
use crate::rgb::Rgb;

/// Whether `path` names a glTF file (extension `gltf` or `glb`, any case).
pub(super) fn is_gltf(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| {
        let e = e.to_ascii_lowercase();
        e == "gltf" || e == "glb"
    })
}

/// Loads a glTF file: its faces (in the order the module docs give) and materials (in file order).
pub(super) fn load_gltf(
    file: &Path,
    warnings: &mut Vec<SceneWarning>,
) -> Result<(Vec<Face>, Vec<Material>), SceneError> {
    let bytes = std::fs::read(file).map_err(|source| SceneError::Io { file: file.to_path_buf(), source })?;
    let parse = |problem: String| SceneError::GltfParse { file: file.to_path_buf(), problem };
    // The `gltf` crate (1.4) subtracts the 12-byte header from a GLB's declared length unchecked (a panic with
    // overflow checks on, found by the fuzz target `gltf`).
    if let Some(declared) = bytes.strip_prefix(b"glTF").and_then(|r| r.get(4..8)) {
        let declared = u32::from_le_bytes([declared[0], declared[1], declared[2], declared[3]]);
        if declared < 12 {
            return Err(parse(format!(
                "GLB header declares a length of {declared} bytes, less than the header's 12"
            )));
        }
    }
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| parse(e.to_string()))?;
    let json = document.into_json();
    check_attribute_indices(&json).map_err(parse)?;
    let document = gltf::Document::from_json(json).map_err(|e| parse(e.to_string()))?;
    let base = match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let at = |place: String, problem: String| SceneError::Gltf { file: file.to_path_buf(), place, problem };
    let buffers = load_buffers(&document, &base, blob, &at)?;
    let materials = build_materials(&document, &base, &buffers, &at)?;
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or_else(|| at("scenes".to_owned(), "the file has no scene (nothing to load)".to_owned()))?;
    check_hierarchy(&document, &scene, &at)?;
    let mut faces = Vec::new();
    let mut stack: Vec<(gltf::Node<'_>, DMat4)> =
        scene.nodes().collect::<Vec<_>>().into_iter().rev().map(|n| (n, DMat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * local_transform(&node, &at)?;
        if let Some(mesh) = node.mesh() {
            let ignored =
                match (node.skin().is_some(), mesh.primitives().any(|p| p.morph_targets().len() > 0)) {
                    (true, true) => Some("skin and morph targets"),
                    (true, false) => Some("skin"),
                    (false, true) => Some("morph targets"),
                    (false, false) => None,
                };
            if let Some(what) = ignored {
                warnings.push(SceneWarning {
                    file: file.to_path_buf(),
                    line: None,
                    face: None,
                    message: format!(
                        "{}: {what} ignored: the mesh is placed as its positions and the node's transform say \
                         (static geometry)",
                        named("node", node.name(), node.index())
                    ),
                });
            }
            add_mesh(file, &node, &mesh, world, &buffers, &materials, &mut faces, &at)?;
        }
        let children: Vec<_> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world)));
    }
    if faces.is_empty() {
        return Err(SceneError::NoFaces { file: file.to_path_buf() });
    }
    warnings.extend(material_warnings(file, &document, &faces));
    Ok((faces, materials))
}

/// Checks that every primitive attribute names an accessor that exists. The `gltf` crate's schema check (1.4)
/// reads the POSITION accessor before it checks the index, and panics on one out of range; this runs first.
fn check_attribute_indices(json: &gltf::json::Root) -> Result<(), String> {
    let n = json.accessors.len();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if let Some(index) = primitive.attributes.values().find(|i| i.value() >= n) {
                return Err(format!(
                    "meshes[{m}].primitives[{p}].attributes: accessor {} does not exist ({n} accessors)",
                    index.value()
                ));
            }
        }
    }
    Ok(())
}

/// Checks what the `gltf` crate's accessor reader (1.4) assumes without checking, and panics on otherwise: the
/// element type, at least one element, a buffer view, a stride no shorter than an element. Sparse accessors
/// (used for morph targets, rarely for geometry) are not read.
fn check_accessor(
    accessor: &gltf::Accessor<'_>,
    what: &str,
    types: &[gltf::accessor::DataType],
    dimensions: gltf::accessor::Dimensions,
) -> Result<(), String> {
    let index = accessor.index();
    if !types.contains(&accessor.data_type()) || accessor.dimensions() != dimensions || accessor.normalized()
    {
        return Err(format!(
            "{what} (accessor {index}) is {:?} {:?}{}; it must be {dimensions:?} of {types:?}",
            accessor.data_type(),
            accessor.dimensions(),
            if accessor.normalized() { " normalized" } else { "" }
        ));
    }
    if accessor.count() == 0 {
        return Err(format!("{what} (accessor {index}) has no elements"));
    }
    if accessor.sparse().is_some() {
        return Err(format!("{what} (accessor {index}) is sparse, which this loader does not read"));
    }
    let Some(view) = accessor.view() else {
        return Err(format!("{what} (accessor {index}) has no buffer view"));
    };
    if view.stride().is_some_and(|s| s < accessor.size()) {
        return Err(format!(
            "{what} (accessor {index}): bufferView {} has byteStride {}, shorter than an element ({} bytes)",
            view.index(),
            view.stride().unwrap_or(0),
            accessor.size()
        ));
    }
    Ok(())
}

/// A place in the file for messages: `what 'name' (index)` or `what index`.
fn named(what: &str, name: Option<&str>, index: usize) -> String {
    match name {
        Some(n) => format!("{what} '{n}' ({index})"),
        None => format!("{what} {index}"),
    }
}

/// Reads every buffer (the GLB binary chunk, a base64 data URI, or a file relative to `base`) and checks that
/// every buffer view lies inside its buffer, so that no later read can go out of bounds.
fn load_buffers(
    document: &gltf::Document,
    base: &Path,
    mut blob: Option<Vec<u8>>,
    at: &impl Fn(String, String) -> SceneError,
) -> Result<Vec<gltf::buffer::Data>, SceneError> {
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let place = match buffer.source() {
            gltf::buffer::Source::Bin => format!("buffer {} (GLB binary chunk)", buffer.index()),
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                format!("buffer {} (data URI)", buffer.index())
            }
            gltf::buffer::Source::Uri(uri) => {
                format!("buffer {} ('{}')", buffer.index(), base.join(uri).display())
            }
        };
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            check_external(base, uri).map_err(|p| at(place.clone(), p))?;
        }
        let data = gltf::buffer::Data::from_source_and_blob(buffer.source(), Some(base), &mut blob)
            .map_err(|e| at(place.clone(), format!("cannot be read: {e}")))?;
        if data.len() < buffer.length() {
            return Err(at(
                place,
                format!(
                    "has {} bytes, less than its byteLength {} (truncated?)",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        buffers.push(data);
    }
    for view in document.views() {
        let len = buffers.get(view.buffer().index()).map_or(0, |d| d.len());
        let end = view.offset().checked_add(view.length());
        if end.is_none_or(|end| end > len) {
            return Err(at(
                format!("bufferView {}", view.index()),
                format!(
                    "bytes {}..{} lie outside buffer {} ({len} bytes)",
                    view.offset(),
                    view.offset().saturating_add(view.length()),
                    view.buffer().index()
                ),
            ));
        }
    }
    Ok(buffers)
}

/// Checks an external buffer or image URI before the `gltf` crate (1.4) reads it, resolved as the crate
/// resolves it: a `file://` or `file:` URI is the path after the prefix, a URI without a scheme is
/// percent-decoded and taken relative to `base`; data URIs and other schemes are left to the crate (which decodes
/// the one and refuses the others). The crate's decoding panics on a percent escape that is not UTF-8, and it
/// would read a device such as `/dev/zero` until memory runs out: both are refused here, naming the URI.
fn check_external(base: &Path, uri: &str) -> Result<(), String> {
    let path =
        if uri.contains(':') {
            match uri.strip_prefix("file://").or_else(|| uri.strip_prefix("file:")) {
                Some(rest) => PathBuf::from(rest),
                None => return Ok(()),
            }
        } else {
            base.join(percent_decode(uri).ok_or_else(|| {
                format!("URI '{uri}' is not UTF-8 text once its percent escapes are decoded")
            })?)
        };
    match std::fs::metadata(&path) {
        Ok(m) if !m.is_file() => {
            Err(format!("URI '{uri}' names '{}', which is not a regular file", path.display()))
        }
        // A missing or unreadable file is reported by the crate's read, with the OS's reason.
        _ => Ok(()),
    }
}

/// `text` with its `%XX` escapes (two hex digits) decoded, as `gltf` 1.4 decodes a relative URI (other `%`
/// signs stay as they are); `None` if the result is not UTF-8.
fn percent_decode(text: &str) -> Option<String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut k = 0;
    while k < bytes.len() {
        let hex = |b: u8| char::from(b).to_digit(16);
        match (bytes[k], bytes.get(k + 1).copied().and_then(hex), bytes.get(k + 2).copied().and_then(hex)) {
            (b'%', Some(hi), Some(lo)) => {
                out.push((hi * 16 + lo) as u8);
                k += 3;
            }
            (b, _, _) => {
                out.push(b);
                k += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

/// The file's materials, checked like MTL ones (reflectance in `[0, 1)`, emission finite and `>= 0`).
fn build_materials(
    document: &gltf::Document,
    base: &Path,
    buffers: &[gltf::buffer::Data],
    at: &impl Fn(String, String) -> SceneError,
) -> Result<Vec<Material>, SceneError> {
    let mut out: Vec<Material> = Vec::new();
    let mut names: HashMap<String, usize> = HashMap::new();
    let mut texture_means: HashMap<usize, Rgb> = HashMap::new();
    for (i, m) in document.materials().enumerate() {
        let name = m.name().map_or_else(|| format!("material_{i}"), str::to_owned);
        let place = named("material", Some(&name), i);
        if let Some(first) = names.insert(name.clone(), i) {
            return Err(at(
                place,
                format!("the name is also material {first}'s (material names must be unique)"),
            ));
        }
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        let mut reflectance = Rgb::new(f64::from(r), f64::from(g), f64::from(b));
        if let Some(info) = pbr.base_color_texture() {
            let what = format!("{place}, base colour texture {}", info.texture().index());
            reflectance *= texture_mean(&info.texture(), base, buffers, &mut texture_means, &what, at)?;
        }
        let strength = m.emissive_strength().unwrap_or(1.0);
        let [er, eg, eb] = m.emissive_factor();
        let mut emission = Rgb::new(f64::from(er), f64::from(eg), f64::from(eb)) * f64::from(strength);
        if let Some(info) = m.emissive_texture() {
            let what = format!("{place}, emissive texture {}", info.texture().index());
            emission *= texture_mean(&info.texture(), base, buffers, &mut texture_means, &what, at)?;
        }
        for (c, &v) in reflectance.to_array().iter().enumerate() {
            if !v.is_finite() {
                return Err(at(place, format!("reflectance (base colour) channel {c} is not finite ({v})")));
            }
            if !(0.0..1.0).contains(&v) {
                return Err(at(
                    place,
                    format!("reflectance (base colour) channel {c} = {v} is outside [0, 1)"),
                ));
            }
        }
        if !(strength.is_finite() && strength >= 0.0) {
            return Err(at(
                place,
                format!(
                    "emissiveStrength (KHR_materials_emissive_strength) {strength} must be finite and >= 0"
                ),
            ));
        }
        for (c, &v) in emission.to_array().iter().enumerate() {
            if !v.is_finite() {
                return Err(at(place, format!("emission channel {c} is not finite ({v})")));
            }
            if v < 0.0 {
                return Err(at(place, format!("emission channel {c} = {v} is negative")));
            }
        }
        out.push(Material { name, reflectance, emission });
    }
    Ok(out)
}

/// The mean linear RGB of a texture's image (decoded once per image), from sRGB-encoded 8- or 16-bit texels.
fn texture_mean(
    texture: &gltf::Texture<'_>,
    base: &Path,
    buffers: &[gltf::buffer::Data],
    cache: &mut HashMap<usize, Rgb>,
    what: &str,
    at: &impl Fn(String, String) -> SceneError,
) -> Result<Rgb, SceneError> {
    let image = texture.source();
    if let Some(&mean) = cache.get(&image.index()) {
        return Ok(mean);
    }
    let place = match image.source() {
        gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => {
            format!("{what}, image {} ('{}')", image.index(), base.join(uri).display())
        }
        _ => format!("{what}, image {}", image.index()),
    };
    if let gltf::image::Source::Uri { uri, .. } = image.source() {
        check_external(base, uri).map_err(|p| at(place.clone(), p))?;
    }
    let data = gltf::image::Data::from_source(image.source(), Some(base), buffers)
        .map_err(|e| at(place.clone(), format!("cannot be decoded: {e}")))?;
    use gltf::image::Format;
    let (channels, bytes) = match data.format {
        Format::R8 => (1, 1),
        Format::R8G8 => (2, 1),
        Format::R8G8B8 => (3, 1),
        Format::R8G8B8A8 => (4, 1),
        Format::R16 => (1, 2),
        Format::R16G16 => (2, 2),
        Format::R16G16B16 => (3, 2),
        Format::R16G16B16A16 => (4, 2),
        other => {
            return Err(at(place, format!("texel format {other:?} is not an 8- or 16-bit sRGB colour")));
        }
    };
    let texel = channels * bytes;
    let count = data.pixels.len() / texel;
    if count == 0 || data.pixels.len() % texel != 0 {
        return Err(at(
            place,
            format!("decodes to {} bytes, not whole {texel}-byte texels", data.pixels.len()),
        ));
    }
    let lut: Vec<f64> = (0..256).map(|v| srgb_to_linear(f64::from(v as u8) / 255.0)).collect();
    let value = |t: &[u8], c: usize| -> f64 {
        if bytes == 1 {
            lut[usize::from(t[c])]
        } else {
            srgb_to_linear(f64::from(u16::from_ne_bytes([t[2 * c], t[2 * c + 1]])) / 65535.0)
        }
    };
    let mut sum = Rgb::ZERO;
    for t in data.pixels.chunks_exact(texel) {
        // One or two channels are grey (luma, luma + alpha); alpha is not colour.
        sum += if channels < 3 {
            Rgb::splat(value(t, 0))
        } else {
            Rgb::new(value(t, 0), value(t, 1), value(t, 2))
        };
    }
    let mean = sum / count as f64;
    cache.insert(image.index(), mean);
    Ok(mean)
}

/// The sRGB transfer function's inverse (IEC 61966-2-1): an encoded value in `[0, 1]` to linear.
fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Checks that the node graph under `scene` is a set of trees, as the spec requires: no node is the child of
/// two nodes (or of itself), and the scene's root nodes are nobody's children. A graph that passes has no cycle
/// reachable from the roots, so the walk ends.
fn check_hierarchy(
    document: &gltf::Document,
    scene: &gltf::Scene<'_>,
    at: &impl Fn(String, String) -> SceneError,
) -> Result<(), SceneError> {
    let mut parent: HashMap<usize, usize> = HashMap::new();
    for node in document.nodes() {
        for child in node.children() {
            if let Some(other) = parent.insert(child.index(), node.index()) {
                return Err(at(
                    named("node", child.name(), child.index()),
                    format!(
                        "is a child of both node {other} and node {} (the node hierarchy must be trees)",
                        node.index()
                    ),
                ));
            }
        }
    }
    let mut roots = HashSet::new();
    for root in scene.nodes() {
        if let Some(p) = parent.get(&root.index()) {
            return Err(at(
                named("node", root.name(), root.index()),
                format!("is a root of scene {} and also a child of node {p}", scene.index()),
            ));
        }
        if !roots.insert(root.index()) {
            return Err(at(
                named("node", root.name(), root.index()),
                format!("is listed twice among the roots of scene {}", scene.index()),
            ));
        }
    }
    Ok(())
}

/// A node's own transform in f64: its matrix, or translation * rotation * scale.
fn local_transform(
    node: &gltf::Node<'_>,
    at: &impl Fn(String, String) -> SceneError,
) -> Result<DMat4, SceneError> {
    let place = || named("node", node.name(), node.index());
    let f = |v: f32| f64::from(v);
    let m = match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => DMat4::from_cols_array_2d(&matrix.map(|c| c.map(f))),
        gltf::scene::Transform::Decomposed { translation, rotation, scale } => {
            let q = DQuat::from_array(rotation.map(f));
            let len = q.length();
            if !(len.is_finite() && len > 0.0) {
                return Err(at(place(), format!("rotation {rotation:?} is not a rotation (length {len})")));
            }
            DMat4::from_scale_rotation_translation(
                DVec3::from_array(scale.map(f)),
                q / len,
                DVec3::from_array(translation.map(f)),
            )
        }
    };
    if !m.is_finite() {
        return Err(at(place(), "transform is not finite".to_owned()));
    }
    // glTF transforms are affine (the spec: decomposable into translation, rotation and scale); a projective
    // bottom row would be ignored by the point transform below, so it is refused.
    if m.row(3) != glam::DVec4::W {
        return Err(at(place(), format!("matrix's last row is {}, not (0, 0, 0, 1): not affine", m.row(3))));
    }
    Ok(m)
}

/// The triangles of a primitive as vertex-index triples in the file's winding, with the triangle numbers used in
/// messages (strip triangles that join strips are skipped, keeping the numbering of the others).
fn triangles(
    mode: Mode,
    indices: &[u32],
    place: &str,
    at: &impl Fn(String, String) -> SceneError,
) -> Result<Vec<(usize, [u32; 3])>, SceneError> {
    let n = indices.len();
    match mode {
        Mode::Triangles => {
            if !n.is_multiple_of(3) {
                return Err(at(place.to_owned(), format!("{n} vertices for TRIANGLES, not a multiple of 3")));
            }
            Ok(indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).enumerate().collect())
        }
        Mode::TriangleStrip | Mode::TriangleFan if n < 3 => {
            Err(at(place.to_owned(), format!("{n} vertices for a triangle strip or fan, fewer than 3")))
        }
        Mode::TriangleStrip => Ok((0..n - 2)
            .map(|p| {
                let (a, b, c) = (indices[p], indices[p + 1], indices[p + 2]);
                (p, if p % 2 == 0 { [a, b, c] } else { [b, a, c] })
            })
            .filter(|(_, [a, b, c])| a != b && b != c && a != c)
            .collect()),
        // The spec's fan triangle p is (p + 1, p + 2, 0): the same turn as (0, p + 1, p + 2).
        Mode::TriangleFan => {
            Ok((0..n - 2).map(|p| (p, [indices[0], indices[p + 1], indices[p + 2]])).collect())
        }
        other => Err(at(
            place.to_owned(),
            format!("mode {other:?} is not a surface (only TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN are)"),
        )),
    }
}

/// Why a primitive without a material is refused.
const NO_MATERIAL: &str =
    "no material (glTF's default material has reflectance 1, which no diffuse surface has)";

/// Places every primitive of `mesh` with the node's world transform and appends its faces.
#[allow(clippy::too_many_arguments)] // one call site; the arguments are the walk's state
fn add_mesh(
    file: &Path,
    node: &gltf::Node<'_>,
    mesh: &gltf::Mesh<'_>,
    world: DMat4,
    buffers: &[gltf::buffer::Data],
    materials: &[Material],
    faces: &mut Vec<Face>,
    at: &impl Fn(String, String) -> SceneError,
) -> Result<(), SceneError> {
    let det = world.determinant();
    let node_place = named("node", node.name(), node.index());
    if !(det.is_finite() && det != 0.0) {
        return Err(at(
            node_place,
            format!("transform (composed with its parents') has determinant {det}: it flattens the mesh"),
        ));
    }
    let object = node.name().map_or_else(|| format!("node {}", node.index()), str::to_owned);
    for primitive in mesh.primitives() {
        let mut place = GltfPlace {
            node: node.index(),
            node_name: node.name().map(str::to_owned),
            mesh: mesh.index(),
            mesh_name: mesh.name().map(str::to_owned),
            primitive: primitive.index(),
            triangles: 0..0,
        };
        let prim_place = format!(
            "{node_place}, {}, primitive {}",
            named("mesh", mesh.name(), mesh.index()),
            primitive.index()
        );
        let Some(material) = primitive.material().index().filter(|&m| m < materials.len()) else {
            return Err(at(prim_place, NO_MATERIAL.to_owned()));
        };
        let Some(accessor) = primitive.get(&Semantic::Positions) else {
            return Err(at(prim_place, "no POSITION attribute".to_owned()));
        };
        use gltf::accessor::{DataType, Dimensions};
        check_accessor(&accessor, "POSITION", &[DataType::F32], Dimensions::Vec3)
            .map_err(|p| at(prim_place.clone(), p))?;
        if let Some(acc) = primitive.indices() {
            check_accessor(
                &acc,
                "indices",
                &[DataType::U8, DataType::U16, DataType::U32],
                Dimensions::Scalar,
            )
            .map_err(|p| at(prim_place.clone(), p))?;
        }
        let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| d.0.as_slice()));
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .map(Iterator::collect)
            .filter(|p: &Vec<[f32; 3]>| p.len() == accessor.count())
            .ok_or_else(|| at(prim_place.clone(), "POSITION data lies outside its buffer view".to_owned()))?;
        let indices: Vec<u32> = match primitive.indices() {
            None => (0..u32::try_from(positions.len()).unwrap_or(u32::MAX)).collect(),
            Some(acc) => reader
                .read_indices()
                .map(|r| r.into_u32().collect())
                .filter(|v: &Vec<u32>| v.len() == acc.count())
                .ok_or_else(|| {
                    at(prim_place.clone(), "index data lies outside its buffer view".to_owned())
                })?,
        };
        let tris = triangles(primitive.mode(), &indices, &prim_place, at)?;
        // Each triangle's vertices in world space, in the order that keeps its front where the file says.
        let vertex = |t: usize, k: usize, i: u32| -> Result<DVec3, SceneError> {
            let tri_place = format!("{prim_place}, triangle {t}");
            let Some(p) = positions.get(i as usize) else {
                return Err(at(
                    tri_place,
                    format!("vertex {k}: index {i} out of range (POSITION has {} vertices)", positions.len()),
                ));
            };
            let p = DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            if !p.is_finite() {
                return Err(at(tri_place, format!("vertex {k} (index {i}) is not finite ({p})")));
            }
            let w = world.transform_point3(p);
            if !w.is_finite() {
                return Err(at(
                    tri_place,
                    format!("vertex {k} (index {i}) at {p} is not finite after the node's transform ({w})"),
                ));
            }
            Ok(w)
        };
        let oriented = |mut v: Vec<DVec3>| {
            if det < 0.0 {
                v.reverse();
            }
            v
        };
        let relocate = |e: SceneError, t: std::ops::Range<usize>| match e {
            SceneError::DegenerateFace { problem, .. } => {
                at(format!("{prim_place}, triangle {}", t.start), format!("degenerate triangle: {problem}"))
            }
            SceneError::NonConvexFace { problem, .. } => at(
                format!("{prim_place}, triangles {}..={}", t.start, t.end - 1),
                format!("non-convex face: {problem}"),
            ),
            other => other,
        };
        // The fan being joined: its vertex indices in file order, its face, its first and last triangle numbers.
        let mut fan: Option<(Vec<u32>, Face, usize, usize)> = None;
        let mut scratch = Vec::new();
        for (t, [a, b, c]) in tris {
            let corners = vec![vertex(t, 0, a)?, vertex(t, 1, b)?, vertex(t, 2, c)?];
            let single = build_face(file, 0, 0, &object, material, oriented(corners), &mut scratch)
                .map_err(|e| relocate(e, t..t + 1))?;
            if let Some((ids, face, _, last)) = fan.as_mut() {
                // A fan continues when the triangle starts at its first vertex and its last one, adds a new
                // vertex, and the union is one planar convex polygon facing the same way.
                if ids.first() == Some(&a) && ids.last() == Some(&b) && !ids.contains(&c) {
                    let mut joined = face.vertices.clone();
                    let new = single.vertices[if det < 0.0 { 0 } else { 2 }];
                    if det < 0.0 {
                        joined.insert(0, new);
                    } else {
                        joined.push(new);
                    }
                    scratch.clear();
                    if let Ok(j) = build_face(file, 0, 0, &object, material, joined, &mut scratch) {
                        if !j.is_split() && scratch.is_empty() && j.normal.dot(single.normal) > 0.0 {
                            ids.push(c);
                            *face = j;
                            *last = t;
                            continue;
                        }
                    }
                    scratch.clear();
                }
            }
            if let Some((_, face, first, last)) = fan.take() {
                push_face(faces, face, &mut place, first..last + 1);
            }
            fan = Some((vec![a, b, c], single, t, t));
        }
        if let Some((_, face, first, last)) = fan.take() {
            push_face(faces, face, &mut place, first..last + 1);
        }
    }
    Ok(())
}

/// Appends `face`, numbered next, with its place (`place` with the triangles it is made of).
fn push_face(
    faces: &mut Vec<Face>,
    mut face: Face,
    place: &mut GltfPlace,
    triangles: std::ops::Range<usize>,
) {
    place.triangles = triangles;
    face.index = faces.len();
    face.line = 0;
    face.gltf = Some(place.clone());
    faces.push(face);
}

/// Warnings about materials that faces use and that this tool reads differently from a renderer: metallic ones
/// (a metal's base colour is its specular colour; here it is a diffuse reflectance) and double-sided ones (here
/// only the front of a face emits and receives light).
fn material_warnings(file: &Path, document: &gltf::Document, faces: &[Face]) -> Vec<SceneWarning> {
    let used: HashSet<usize> = faces.iter().map(|f| f.material).collect();
    let mut out = Vec::new();
    for (i, m) in document.materials().enumerate() {
        if !used.contains(&i) {
            continue;
        }
        let place = named("material", m.name(), i);
        let warn =
            |message: String| SceneWarning { file: file.to_path_buf(), line: None, face: None, message };
        let metallic = m.pbr_metallic_roughness().metallic_factor();
        if metallic > 0.0 {
            out.push(warn(format!(
                "{place}: metallicFactor is {metallic} (glTF's default is 1); this tool treats every surface as \
                 diffuse, with the base colour as its reflectance"
            )));
        }
        if m.double_sided() {
            out.push(warn(format!(
                "{place}: double-sided; here only the front of a face (counter-clockwise seen from it) emits and \
                 receives light"
            )));
        }
    }
    out
}
