//! Scene loading: a Wavefront OBJ + MTL pair or a glTF 2.0 file (and an optional `NAME.toml` beside either)
//! turned into validated faces, materials and light groups.
//!
//! # glTF
//! A path ending in `.gltf` or `.glb` is read as glTF 2.0 (submodule `gltf`, whose docs give the mapping): every
//! triangle, or fan of triangles joined into a polygon, is a [`Face`]; materials take their reflectance from the
//! base colour and their emission, in W/m^2 as MTL `Ke`, from the emissive factor and strength. Everything from
//! the checks of the faces on (extent, overlaps, the TOML file, light groups) is the same as for OBJ; errors
//! name the node, mesh, primitive and triangle instead of a line ([`Face::place`]).
//!
//! # Format
//! - Geometry: OBJ `v` and `f` statements, read with `tobj` without triangulation, so every face is the polygon
//!   the file wrote. Faces are numbered 0, 1, 2, ... in OBJ order over all objects: [`Scene::faces`]`[k]` is the
//!   k-th `f` statement of the file. A face's normal follows its vertex order (counter-clockwise seen from the
//!   side the normal points to, the right-hand rule); only that side emits and receives light.
//! - Materials: MTL `Kd` is the reflectance (per channel, in `[0, 1)`, required), `Ke` the emission as radiant
//!   exitance in W/m^2 (per channel, finite and `>= 0`, default 0). A colour with one number (`Kd 0.5`) is grey:
//!   the same value on all three channels.
//! - `NAME.toml` (optional, beside `NAME.obj`; the user reference, with an annotated example of every field, is
//!   `docs/scene-format.md`, whose examples a test loads):
//!   ```toml
//!   [meshing]
//!   max_patch_edge = 100.0   # scene units; largest patch edge after uniform subdivision
//!   patch_budget = 2000      # most patches the mesh may have (uniform plus adaptive)
//!   refine_passes = 3        # adaptive refinement passes after uniform subdivision (0: uniform only)
//!   refine_tolerance = 0.05  # refine where radiosity changes by more than this times the mean radiosity
//!   repair = true            # cut faces where others meet them, cull hidden pieces (default true)
//!
//!   [[light_group]]
//!   name = "light"
//!   materials = ["light"]    # emitting materials that belong to the group
//!   dynamic = true           # false: folded into the static base at bake time (default true)
//!   intensity = [1.0, 1.0, 1.0]  # default intensity, RGB or one number (default 1)
//!   ```
//!   Every material with a nonzero `Ke` that no `[[light_group]]` lists becomes its own dynamic light group,
//!   named after the material, at intensity 1.
//!
//! # Validation
//! [`Scene::load`] returns a [`SceneError`] naming the file, the line and (for faces) the face index, for: a
//! missing or unreadable file, an OBJ/MTL/TOML syntax error, a face without a defined material, a reflectance
//! outside `[0, 1)`, a negative or non-finite value, a face with fewer than three vertices, non-finite or
//! repeated vertices or zero area (degenerate), a non-convex face, a face too far from planar, and coplanar faces
//! that overlap with positive area (duplicates included), and a scene whose size or distance from the origin is
//! outside the supported range (`extent`: [`MIN_SCENE_SIZE`], [`MAX_SCENE_SIZE`], [`MAX_ORIGIN_DISTANCE`]).
//! It warns ([`Scene::warnings`]) about a non-planar face split into triangles, a light group whose materials no
//! face uses, a scene in which no face emits, and faces that face each other across a gap narrower than the rays
//! can resolve (`overlap`: twice the scene's size / 8192). Nothing in this module panics on any input. The
//! tolerances are relative to each face's size ([`PLANAR_TOLERANCE`], [`NON_PLANAR_LIMIT`],
//! [`DEGENERATE_TOLERANCE`], [`OVERLAP_TOLERANCE`]; the reasoning behind each is in the submodule that uses it).
//!
//! # Where things are
//! Loading runs the submodules in this order; each uses only those before it.
//! - `polygon`: [`Polygon`], a planar convex polygon with normal, area and centroid (shared with meshing).
//! - `error`: [`SceneError`] and [`SceneWarning`].
//! - `obj`: reading the OBJ and MTL text with `tobj`, and the line numbers `tobj` does not report.
//! - `material`: [`Material`]s checked (`Kd`, `Ke`).
//! - `face`: [`Face`]s built and checked (degenerate, convex, planar or split into a fan), with the face
//!   tolerances, and [`GltfPlace`].
//! - `gltf`: a glTF file's nodes, meshes and materials turned into faces and materials with the checks of
//!   `face` (the glTF path's counterpart of `obj`, `material` and `face`'s `build_faces`).
//! - `extent`: the scene's size and position against the supported range.
//! - `overlap`: the coplanar-overlap check between faces, and the narrow-gap warning.
//! - `config`: the `NAME.toml` file and its [`MeshingLimits`].
//! - `light_group`: [`LightGroup`]s from the TOML file and the emitting materials, and the warnings about light
//!   that cannot be emitted.
//! - `gltf_write`: the way back, a loaded scene written as glTF ([`SceneGltf`], `radiosity convert`), and the
//!   `.glb` container ([`glb_container`]) that the light-map export shares.
//!
//! This module depends on no later stage: meshing ([`crate::mesh`]) reads the scene, never the other way.

mod config;
mod error;
mod extent;
mod face;
mod gltf;
mod gltf_write;
mod light_group;
mod material;
mod obj;
mod overlap;
mod polygon;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

pub use config::{MeshingLimits, MAX_REFINE_PASSES};
pub(crate) use error::length;
pub use error::{SceneError, SceneWarning};
pub use extent::{bounding_box, MAX_ORIGIN_DISTANCE, MAX_SCENE_SIZE, MIN_SCENE_SIZE};
pub use face::{Face, GltfPlace, DEGENERATE_TOLERANCE, NON_PLANAR_LIMIT, PLANAR_TOLERANCE};
pub use gltf_write::{glb_container, SceneGltf};
pub use light_group::LightGroup;
pub use material::Material;
pub use overlap::OVERLAP_TOLERANCE;
pub use polygon::Polygon;

use config::{check_meshing, parse_config, TomlScene};
use extent::check_extent;
use face::build_faces;
use gltf::{is_gltf, load_gltf};
use light_group::{build_light_groups, light_warnings};
use material::check_materials;
use obj::{load_obj, read_text};
use overlap::{check_overlaps, narrow_gaps};

/// A loaded, validated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The OBJ or glTF file the scene came from.
    pub path: PathBuf,
    /// Faces in OBJ order (for glTF, in the order the [`gltf`](self#gltf) section gives).
    pub faces: Vec<Face>,
    /// Materials of all MTL files, in the order they were defined (for glTF: the file's materials, in order).
    pub materials: Vec<Material>,
    /// Light groups: first those of the TOML file in its order, then one per emitting material it does not
    /// list, in material order.
    pub light_groups: Vec<LightGroup>,
    /// Meshing limits from the TOML file.
    pub meshing: MeshingLimits,
    /// Problems that did not stop loading (non-planar faces split into triangles, light groups without faces, no
    /// emitting face). Not printed here: the command line prints them on stderr.
    pub warnings: Vec<SceneWarning>,
}

/// Whether `path` names a file [`Scene::load`] reads as a scene: extension `obj`, `gltf` or `glb` (any case).
/// A folder of scenes lists its scenes with it (`regress` does); the MTL, TOML, buffer and image files beside
/// them are not scenes.
#[must_use]
pub fn is_scene_file(path: &Path) -> bool {
    is_gltf(path) || path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("obj"))
}

impl Scene {
    /// Loads `NAME.obj` and the MTL files it names (relative to its folder), or `NAME.gltf` / `NAME.glb` and the
    /// buffers and images it names, and `NAME.toml` if it exists.
    ///
    /// # Errors
    /// A [`SceneError`] naming the file, and the line and face (OBJ) or the node, mesh, primitive and triangle
    /// (glTF) of the first problem found.
    pub fn load(obj_path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        let obj_path = obj_path.as_ref();
        let toml_path = obj_path.with_extension("toml");
        let toml = if toml_path.is_file() { Some(toml_path) } else { None };
        Scene::load_with_toml(obj_path, toml.as_deref())
    }

    /// Loads `obj_path` and its MTL files (or, for a path ending in `.gltf` or `.glb`, that glTF file and its
    /// buffers and images), and takes light groups and meshing limits from `toml_path` if given.
    ///
    /// # Errors
    /// A [`SceneError`] naming the file, and the line and face (OBJ) or the node, mesh, primitive and triangle
    /// (glTF) of the first problem found.
    pub fn load_with_toml(obj_path: &Path, toml_path: Option<&Path>) -> Result<Scene, SceneError> {
        let mut warnings = Vec::new();
        let (faces, materials, sources) = if is_gltf(obj_path) {
            let (faces, materials) = load_gltf(obj_path, &mut warnings)?;
            (faces, materials, HashMap::new())
        } else {
            let text = read_text(obj_path)?;
            let obj = load_obj(obj_path, &text)?;
            let materials = check_materials(&obj)?;
            let faces = build_faces(obj_path, &obj, &materials, &mut warnings)?;
            (faces, materials, obj.sources)
        };
        check_extent(obj_path, &faces)?;
        check_overlaps(obj_path, &faces)?;
        warnings.extend(narrow_gaps(obj_path, &faces));
        let settings = match toml_path {
            Some(p) => parse_config(p, &read_text(p)?)?,
            None => TomlScene::default(),
        };
        let toml_file = toml_path.map_or_else(|| obj_path.with_extension("toml"), Path::to_path_buf);
        let meshing = check_meshing(&toml_file, settings.meshing.as_ref())?;
        let light_groups = build_light_groups(&toml_file, &settings.light_group, &materials)?;
        warnings.extend(light_warnings(obj_path, &sources, &light_groups, &materials, &faces));
        Ok(Scene { path: obj_path.to_path_buf(), faces, materials, light_groups, meshing, warnings })
    }

    /// Total area of all faces.
    #[must_use]
    pub fn total_area(&self) -> f64 {
        self.faces.iter().map(|f| f.area).sum()
    }

    /// The light group a material belongs to, if any (an index into [`Scene::light_groups`]).
    #[must_use]
    pub fn light_group_of(&self, material: usize) -> Option<usize> {
        self.light_groups.iter().position(|g| g.materials.contains(&material))
    }
}
