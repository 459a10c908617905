//! Binary glTF 2.0 (`.glb`) export: the patches as triangle meshes with light-map UVs, and the light map embedded,
//! so game engines and the web show the baked lighting as it is.
//!
//! **Geometry.** Every patch (the polygons the radiosity was solved on, the same ones `radiosity render` traces) is
//! fan-triangulated; each patch has its own vertices (positions in scene units, unconverted: glTF reads them as
//! metres, so scale the node of a scene modelled in millimetres), its normal, and one primitive per material.
//!
//! **UVs.** `TEXCOORD_1` maps a vertex `p` of a patch of face `f` to `(ax / W, ay / H)`, where `(ax, ay)` is
//! [`FaceRect::atlas_coords`] of `p` in `f`'s rectangle and `W x H` the atlas size: the same affine map the light
//! map's texel centres were placed with, so texel `(i, j)` sits at UV `((i + 0.5) / W, (j + 0.5) / H)` on exactly
//! the point whose value it holds (glTF's UV origin is the image's top-left corner, like the atlas's rows). glTF
//! requires `TEXCOORD_0` before `TEXCOORD_1`; it is the same accessor.
//!
//! **What the light map holds.** Engines multiply a light map by the base colour, so the map holds the light
//! *arriving* at the surface, the irradiance `H = (B - E) / rho` per channel (W/m^2; 0 where `rho` is 0), and
//! `baseColorFactor` is the reflectance `rho`: base colour x light map = `B - E`, the reflected radiosity. The
//! embedded PNG is 8-bit sRGB (three.js and Bevy decode it to linear): a texel's linear value `t` in `[0, 1]` stands
//! for `H = t * S`, with `S` (the *irradiance scale*) the largest irradiance of any chart texel, so nothing clips;
//! the 8-bit steps cost at most `S * (srgb_decode((c + 0.5) / 255) - srgb_decode(c / 255))` at code `c`. Emitters
//! carry their emission as `emissiveFactor` (times `KHR_materials_emissive_strength` above 1), as radiance `E / pi`.
//! With the light map's intensity set to `S` and no lights, three.js's `MeshLambertMaterial` (which divides a
//! light map by pi, as `MeshBasicMaterial` does) shows radiance `rho H / pi + E / pi = B / pi` in W/(m^2 sr):
//! multiply the exposure by pi to display radiosity as `radiosity render` does. (`MeshStandardMaterial` takes
//! its specular lobe's share, about 4%, out of the light map; Bevy multiplies the light map by the base colour
//! without dividing by pi, so its `lightmap_exposure` is `S / pi` for the same picture.)
//!
//! **Extensions.** Each material names the light map with `MOZ_lightmap` (`{"index", "texCoord": 1, "intensity":
//! S}`, the Mozilla Hubs convention that three.js-based viewers read); the file's `extras.radiosity` states the same
//! numbers in words, and the suggested tone map. The sampler filters linearly without mip maps and clamps to the
//! edge: the charts' gutters are sized for that ([`super::lightmap`]).
//!
//! The container: a 12-byte header (`glTF`, version 2, total length), a JSON chunk padded with spaces and a binary
//! chunk padded with zeros, each to 4 bytes (glTF 2.0 specification, "Binary glTF Layout"), written by
//! [`crate::scene::glb_container`].

use std::collections::BTreeMap;

use serde_json::{json, Value};

use super::hdr::LinearImage;
use super::lightmap::{FaceRect, LightMap};
use super::tonemap::srgb_encode_u8;
use super::{encode_png, PictureError, RgbImage, ToneMap};
use crate::patch::Patch;
use crate::rgb::Rgb;
use crate::scene::Material;

/// glTF component type of 32-bit floats.
const FLOAT: u32 = 5126;
/// glTF component type of 32-bit unsigned integers.
const UNSIGNED_INT: u32 = 5125;
/// Buffer-view target of vertex attributes.
const ARRAY_BUFFER: u32 = 34962;
/// Buffer-view target of indices.
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// Sampler filter `LINEAR` (no mip maps).
const LINEAR: u32 = 9729;
/// Sampler wrap mode `CLAMP_TO_EDGE`.
const CLAMP_TO_EDGE: u32 = 33071;

/// A `.glb` file made by [`encode_glb`], and what it holds.
#[derive(Clone, Debug, PartialEq)]
pub struct Glb {
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// The irradiance atlas `H = (B - E) / rho` (W/m^2, linear) that the embedded PNG encodes; unused texels are 0.
    pub irradiance: LinearImage,
    /// Irradiance (W/m^2) that a texel of linear value 1 (sRGB code 255) stands for: the light map's intensity.
    pub irradiance_scale: f64,
    /// Triangles written.
    pub triangles: usize,
    /// Vertices written.
    pub vertices: usize,
}

/// The irradiance atlas of `map`: per chart texel `(B - E) / rho` of the face's material, clamped to `>= 0`.
///
/// # Errors
/// [`PictureError::Invalid`] if a face's patches have different materials or a material index is out of range.
pub fn irradiance_atlas(
    patches: &[Patch],
    materials: &[Material],
    map: &LightMap,
) -> Result<LinearImage, PictureError> {
    let material_of = face_materials(patches, materials)?;
    let mut out = LinearImage::new(map.atlas.width, map.atlas.height);
    let w = map.atlas.width as usize;
    for rect in &map.rects {
        let m = &materials[material_of[&rect.face]];
        let (x0, y0, pw, ph) = rect.padded(map.padding);
        for y in y0..y0 + ph {
            for x in x0..x0 + pw {
                let k = y as usize * w + x as usize;
                let b = Rgb::from_array(map.atlas.pixels[k].map(f64::from));
                let h = Rgb::from_array(std::array::from_fn(|c| {
                    if m.reflectance[c] > 0.0 {
                        ((b[c] - m.emission[c]) / m.reflectance[c]).max(0.0)
                    } else {
                        0.0
                    }
                }));
                out.pixels[k] = h.as_vec3().to_array();
            }
        }
    }
    Ok(out)
}

/// The material of every face (all its patches must share it).
fn face_materials(patches: &[Patch], materials: &[Material]) -> Result<BTreeMap<usize, usize>, PictureError> {
    let mut of = BTreeMap::new();
    for (i, p) in patches.iter().enumerate() {
        if p.material >= materials.len() {
            return Err(PictureError::invalid(
                "glTF export",
                format!("patch {i} has material {} of {}", p.material, materials.len()),
            ));
        }
        let first = *of.entry(p.face).or_insert(p.material);
        if first != p.material {
            return Err(PictureError::invalid(
                "glTF export",
                format!(
                    "face {} has patches of materials {:?} and {:?}: one light-map chart needs one material",
                    p.face, materials[first].name, materials[p.material].name
                ),
            ));
        }
    }
    Ok(of)
}

/// The binary chunk under construction: appends 4-byte-aligned buffer views and their accessors.
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut view = json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(view);
        self.views.len() - 1
    }

    fn floats(&mut self, values: &[f32], kind: &str, components: usize, bounds: bool) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ARRAY_BUFFER));
        let count = values.len() / components;
        let mut accessor = json!({"bufferView": view, "componentType": FLOAT, "count": count, "type": kind});
        if bounds {
            let (mut lo, mut hi) = (vec![f32::INFINITY; components], vec![f32::NEG_INFINITY; components]);
            for chunk in values.chunks_exact(components) {
                for (c, &v) in chunk.iter().enumerate() {
                    lo[c] = lo[c].min(v);
                    hi[c] = hi[c].max(v);
                }
            }
            accessor["min"] = json!(lo);
            accessor["max"] = json!(hi);
        }
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn indices(&mut self, values: &[u32]) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(
            json!({"bufferView": view, "componentType": UNSIGNED_INT, "count": values.len(), "type": "SCALAR"}),
        );
        self.accessors.len() - 1
    }
}

/// One material's triangles.
#[derive(Default)]
struct Primitive {
    positions: Vec<f32>,
    normals: Vec<f32>,
    uvs: Vec<f32>,
    indices: Vec<u32>,
}

/// Encodes the scene as a `.glb` (see the module docs): `patches` with their `materials`, the light map `map`
/// baked from the same patches, and `tone`, the tone map suggested for display (recorded in `extras`).
///
/// # Errors
/// [`PictureError::Invalid`] if `map` does not have a rectangle for some patch's face, a face mixes materials, a
/// coordinate is not finite, or the file would exceed glTF's 4 GiB; [`PictureError::Png`] if PNG encoding fails.
pub fn encode_glb(
    patches: &[Patch],
    materials: &[Material],
    map: &LightMap,
    tone: ToneMap,
) -> Result<Glb, PictureError> {
    let rects: BTreeMap<usize, &FaceRect> = map.rects.iter().map(|r| (r.face, r)).collect();
    let (aw, ah) = (f64::from(map.atlas.width), f64::from(map.atlas.height));

    // Geometry, one primitive per material, in material order.
    let mut primitives: BTreeMap<usize, Primitive> = BTreeMap::new();
    let (mut triangles, mut vertices) = (0usize, 0usize);
    for (i, p) in patches.iter().enumerate() {
        let rect = rects.get(&p.face).ok_or_else(|| {
            PictureError::invalid(
                "glTF export",
                format!("patch {i}: face {} has no light-map rectangle", p.face),
            )
        })?;
        if p.vertices.iter().any(|v| !v.is_finite()) || !p.normal.is_finite() {
            return Err(PictureError::invalid(
                "glTF export",
                format!("patch {i} has non-finite coordinates"),
            ));
        }
        let prim = primitives.entry(p.material).or_default();
        let base = u32::try_from(prim.positions.len() / 3)
            .map_err(|_| PictureError::invalid("glTF export", "more than 2^32 vertices in one material"))?;
        let normal = p.normal.as_vec3().normalize();
        for &v in &p.vertices {
            prim.positions.extend(v.as_vec3().to_array());
            prim.normals.extend(normal.to_array());
            let (ax, ay) = rect.atlas_coords(v);
            prim.uvs.extend([(ax / aw) as f32, (ay / ah) as f32]);
        }
        for k in 1..p.vertices.len().saturating_sub(1) as u32 {
            prim.indices.extend([base, base + k, base + k + 1]);
            triangles += 1;
        }
        vertices += p.vertices.len();
    }

    // The light map: irradiance, scaled so that its largest texel is code 255, sRGB encoded.
    let irradiance = irradiance_atlas(patches, materials, map)?;
    let largest = irradiance.pixels.iter().flatten().fold(0.0f32, |m, &v| m.max(v));
    let irradiance_scale = if largest > 0.0 { f64::from(largest) } else { 1.0 };
    let mut png = RgbImage::new(irradiance.width, irradiance.height);
    for (k, px) in irradiance.pixels.iter().enumerate() {
        let code = px.map(|v| srgb_encode_u8(f64::from(v) / irradiance_scale));
        png.pixels[3 * k..3 * k + 3].copy_from_slice(&code);
    }
    let png = encode_png(&png)?;

    let mut b = Builder { bin: Vec::new(), views: Vec::new(), accessors: Vec::new() };
    let mut json_primitives = Vec::new();
    let mut json_materials = Vec::new();
    let mut any_strength = false;
    for (material, prim) in &primitives {
        let position = b.floats(&prim.positions, "VEC3", 3, true);
        let normal = b.floats(&prim.normals, "VEC3", 3, false);
        let uv = b.floats(&prim.uvs, "VEC2", 2, false);
        let indices = b.indices(&prim.indices);
        json_primitives.push(json!({
            "attributes": {"POSITION": position, "NORMAL": normal, "TEXCOORD_0": uv, "TEXCOORD_1": uv},
            "indices": indices,
            "material": json_materials.len(),
            "mode": 4,
        }));
        let m = &materials[*material];
        let mut mat = json!({
            "name": m.name,
            "pbrMetallicRoughness": {
                "baseColorFactor": [m.reflectance.x, m.reflectance.y, m.reflectance.z, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0,
            },
            "extensions": {"MOZ_lightmap": {"index": 0, "texCoord": 1, "intensity": irradiance_scale}},
        });
        let radiance = m.emission / std::f64::consts::PI;
        let peak = radiance.max_element();
        if peak > 0.0 {
            if peak > 1.0 {
                mat["emissiveFactor"] = json!((radiance / peak).to_array());
                mat["extensions"]["KHR_materials_emissive_strength"] = json!({"emissiveStrength": peak});
                any_strength = true;
            } else {
                mat["emissiveFactor"] = json!(radiance.to_array());
            }
        }
        json_materials.push(mat);
    }
    let image_view = b.view(&png, None);

    let mut extensions_used = vec!["MOZ_lightmap"];
    if any_strength {
        extensions_used.push("KHR_materials_emissive_strength");
    }
    let document = json!({
        "asset": {"version": "2.0", "generator": concat!("radiosity-host ", env!("CARGO_PKG_VERSION"))},
        "extensionsUsed": extensions_used,
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "scene", "mesh": 0}],
        "meshes": [{"name": "patches", "primitives": json_primitives}],
        "materials": json_materials,
        "textures": [{"name": "light map", "sampler": 0, "source": 0}],
        "samplers": [{"magFilter": LINEAR, "minFilter": LINEAR, "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE}],
        "images": [{"name": "light map (irradiance, sRGB)", "bufferView": image_view, "mimeType": "image/png"}],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": b.bin.len()}],
        "extras": {"radiosity": {
            "light_map": {
                "texture": 0,
                "texCoord": 1,
                "quantity": "irradiance H = (B - E) / rho per channel, W/m^2: base colour x H = reflected radiosity",
                "encoding": "8-bit sRGB; H = srgb_decode(code / 255) * irradiance_scale",
                "irradiance_scale": irradiance_scale,
                "atlas": [map.atlas.width, map.atlas.height],
                "texel_size": map.texel_size,
                "padding": map.padding,
            },
            "emission": "emissiveFactor x emissiveStrength = E / pi, radiance in W/(m^2 sr)",
            "display": "with the light map's intensity = irradiance_scale, an unlit material shows B / pi; \
                tone_map.exposure is the radiosity tone map's exposure times pi",
            "tone_map": {"operator": "extended Reinhard on Rec. 709 luminance, then sRGB",
                "exposure": tone.scale * std::f64::consts::PI, "white": tone.white},
            "units": "positions in scene units",
        }},
    });
    let text =
        serde_json::to_vec(&document).map_err(|e| PictureError::invalid("glTF JSON", e.to_string()))?;
    let bytes =
        crate::scene::glb_container(&text, &b.bin).map_err(|e| PictureError::invalid("glTF export", e))?;
    Ok(Glb { bytes, irradiance, irradiance_scale, triangles, vertices })
}
