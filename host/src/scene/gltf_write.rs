//! A loaded scene written back as glTF 2.0 (`radiosity convert`): the inverse of the `gltf` loader, so that an
//! OBJ scene can ship as `.glb` (or `.gltf` with its `.bin`) and load as the same scene.
//!
//! # Layout
//! One scene, one root node (`root`, no transform), one mesh (`scene`), and one primitive of indexed `TRIANGLES`
//! per run of consecutive faces with one material, in face order. Each polygon of a face (the face itself, or
//! the triangles of a non-planar face the loader split) is written as a triangle fan from its first vertex over
//! vertices of its own, so the loader joins it back into one polygon and the faces come back in the same order
//! (a split face comes back as its triangles). Positions are the scene's, in its units (glTF reads metres: a
//! scene modelled in millimetres stays in millimetres), rounded to f32 as glTF stores them.
//!
//! # Materials
//! Every material of the scene, in order, with its name: `baseColorFactor` is the reflectance, `metallicFactor`
//! is 0. Emission `E` (W/m^2, as MTL `Ke`) is written as `emissiveFactor = E / max(E)` times
//! `KHR_materials_emissive_strength.emissiveStrength = max(E)`, which the loader multiplies back together.
//! Light groups and meshing limits are not in glTF: they stay in `NAME.toml`, which the loader reads beside
//! `NAME.glb` as beside `NAME.obj`.
//!
//! The output is a pure function of the scene (no version, date or path in it), so a shipped file can be checked
//! against what this writes now.

use serde_json::{json, Value};

use super::Scene;

/// glTF component type of 32-bit floats.
const FLOAT: u32 = 5126;
/// glTF component type of 32-bit unsigned integers.
const UNSIGNED_INT: u32 = 5125;
/// glTF primitive mode `TRIANGLES`.
const TRIANGLES: u32 = 4;
/// The `asset.generator` of every file written here.
const GENERATOR: &str = "radiosity convert";

/// A scene as a glTF document and its binary buffer, ready to be written as `.glb` or `.gltf` + `.bin`.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneGltf {
    /// The JSON document, without the buffer's `uri` (a `.glb` has none; a `.gltf` names its `.bin`).
    document: Value,
    /// The binary buffer: positions and indices, each view aligned to 4 bytes.
    bin: Vec<u8>,
}

impl SceneGltf {
    /// The glTF form of `scene` (see the module docs).
    ///
    /// # Errors
    /// A message naming the face when a coordinate does not fit f32 (it is then not finite in the file), or the
    /// primitive when it has more than 2^32 vertices.
    pub fn of(scene: &Scene) -> Result<SceneGltf, String> {
        let mut bin = Vec::new();
        let (mut views, mut accessors) = (Vec::new(), Vec::new());
        let mut view = |bin: &mut Vec<u8>, bytes: &[u8]| {
            while !bin.len().is_multiple_of(4) {
                bin.push(0);
            }
            views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()}));
            bin.extend_from_slice(bytes);
            views.len() - 1
        };
        let mut primitives = Vec::new();
        for (k, run) in scene.faces.chunk_by(|a, b| a.material == b.material).enumerate() {
            let mut positions: Vec<[f32; 3]> = Vec::new();
            let mut indices: Vec<u32> = Vec::new();
            for face in run {
                for poly in &face.polygons {
                    let first = u32::try_from(positions.len())
                        .map_err(|_| format!("primitive {k}: more than 2^32 vertices"))?;
                    for v in &poly.vertices {
                        let p = v.as_vec3().to_array();
                        if !p.iter().all(|c| c.is_finite()) {
                            return Err(format!(
                                "face {} ({}): vertex {v} does not fit f32, as glTF stores positions",
                                face.index,
                                face.place()
                            ));
                        }
                        positions.push(p);
                    }
                    let n = poly.vertices.len() as u32;
                    for j in 1..n.saturating_sub(1) {
                        indices.extend([first, first + j, first + j + 1]);
                    }
                }
            }
            let bytes: Vec<u8> = positions.iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
            let v = view(&mut bin, &bytes);
            let bound = |f: fn(f32, f32) -> f32, init: f32| -> Vec<f32> {
                (0..3).map(|c| positions.iter().map(|p| p[c]).fold(init, f)).collect()
            };
            accessors.push(json!({
                "bufferView": v, "componentType": FLOAT, "count": positions.len(), "type": "VEC3",
                "min": bound(f32::min, f32::INFINITY), "max": bound(f32::max, f32::NEG_INFINITY),
            }));
            let bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
            let v = view(&mut bin, &bytes);
            accessors.push(
                json!({"bufferView": v, "componentType": UNSIGNED_INT, "count": indices.len(), "type": "SCALAR"}),
            );
            primitives.push(json!({
                "attributes": {"POSITION": accessors.len() - 2},
                "indices": accessors.len() - 1,
                "material": run[0].material,
                "mode": TRIANGLES,
            }));
        }
        let materials: Vec<Value> = scene
            .materials
            .iter()
            .map(|m| {
                let rho = m.reflectance;
                let mut out = json!({
                    "name": m.name,
                    "pbrMetallicRoughness": {"baseColorFactor": [rho.x, rho.y, rho.z, 1.0], "metallicFactor": 0.0},
                });
                let strength = m.emission.max_element();
                if strength > 0.0 {
                    out["emissiveFactor"] = json!((m.emission / strength).to_array());
                    out["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": strength}});
                }
                out
            })
            .collect();
        let mut document = json!({
            "asset": {"version": "2.0", "generator": GENERATOR},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"name": "root", "mesh": 0}],
            "meshes": [{"name": "scene", "primitives": primitives}],
            "materials": materials,
            "accessors": accessors,
            "bufferViews": views,
            "buffers": [{"byteLength": bin.len()}],
        });
        if scene.materials.iter().any(|m| m.emission.max_element() > 0.0) {
            document["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]);
        }
        Ok(SceneGltf { document, bin })
    }

    /// The binary glTF file (`.glb`).
    ///
    /// # Errors
    /// A message if the file would exceed glTF's 4 GiB.
    pub fn to_glb(&self) -> Result<Vec<u8>, String> {
        let json = serde_json::to_vec(&self.document).map_err(|e| format!("glTF JSON: {e}"))?;
        glb_container(&json, &self.bin)
    }

    /// The text glTF file (`.gltf`) whose buffer is the file `bin_uri` (a URI relative to the `.gltf`, e.g.
    /// `NAME.bin`), and that buffer's bytes.
    ///
    /// # Errors
    /// A message if the JSON cannot be written.
    pub fn to_gltf(&self, bin_uri: &str) -> Result<(Vec<u8>, &[u8]), String> {
        let mut document = self.document.clone();
        document["buffers"][0]["uri"] = json!(bin_uri);
        let mut json = serde_json::to_vec_pretty(&document).map_err(|e| format!("glTF JSON: {e}"))?;
        json.push(b'\n');
        Ok((json, &self.bin))
    }
}

/// Binary glTF's container: a 12-byte header (`glTF`, version 2, total length), the JSON chunk padded with
/// spaces and the binary chunk padded with zeros, each to 4 bytes (glTF 2.0 specification, "Binary glTF
/// Layout"). The one writer of `.glb` files (the light-map export uses it too).
///
/// # Errors
/// A message if the file would exceed glTF's 4 GiB.
pub fn glb_container(json: &[u8], bin: &[u8]) -> Result<Vec<u8>, String> {
    let padded = |n: usize| n.div_ceil(4) * 4;
    let (json_len, bin_len) = (padded(json.len()), padded(bin.len()));
    let total = 12 + 8 + json_len + 8 + bin_len;
    let too_big = || format!("{total} bytes: over glTF's 4 GiB limit");
    let total32 = u32::try_from(total).map_err(|_| too_big())?;
    let mut bytes = Vec::with_capacity(total);
    bytes.extend_from_slice(b"glTF");
    bytes.extend_from_slice(&2u32.to_le_bytes());
    bytes.extend_from_slice(&total32.to_le_bytes());
    for (chunk, len, kind, pad) in [(json, json_len, b"JSON", b' '), (bin, bin_len, b"BIN\0", 0)] {
        bytes.extend_from_slice(&u32::try_from(len).map_err(|_| too_big())?.to_le_bytes());
        bytes.extend_from_slice(kind);
        bytes.extend_from_slice(chunk);
        bytes.resize(bytes.len() + len - chunk.len(), pad);
    }
    Ok(bytes)
}
