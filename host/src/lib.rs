//! `radiosity-host`: the workstation side of the radiosity toolkit.
//!
//! Scene loading, meshing into patches, form factors with occlusion rays (`raycast`: Embree in production, a
//! pure-Rust BVH for tests and cross-checks), the f64 reference solve, a path-traced continuous reference,
//! table writing, checks and reports. The physics conventions are those of `radiosity-core`; `rng` is the one random number generator, and
//! [`rgb::Rgb`] (glam's `DVec3`, `x, y, z` = R, G, B) the one colour type of every per-patch reflectance,
//! emission, radiosity and intensity, and [`text::counted`] the one way a message spells a count ("1 patch",
//! "2 patches").
//!
//! # Map
//! The pipeline, in order, and where a change of each kind goes:
//!
//! | stage | module | a change of |
//! |---|---|---|
//! | load | [`scene`] | OBJ/MTL/TOML input |
//! | mesh | [`mesh`], [`patch`] | patches, adaptive refinement, the form-factor matrix type |
//! | form factors | [`formfactor`], [`raycast`], [`embree`] | the estimator, occlusion rays |
//! | prepare | [`pipeline`] | the stages above run together for a command |
//! | hierarchy | [`hierarchy`] (`hierarchy/`: tree, link, solve) | the hierarchical solver with clustering (links instead of a matrix) |
//! | reference | [`reference`](mod@reference), [`lighting`], [`input`], [`rgb`] | the f64 solves, per-patch lighting, the input checks they share, the colour type |
//! | continuous reference | [`montecarlo`] (`montecarlo/`: tracer, report) | the path-traced per-face radiosity with standard errors, independent of the mesh |
//! | bake | [`bake`] (`bake/`: sparsify, solve, ids, state, codec, decode, report, capacities) | how a table is produced (it only produces) |
//! | evaluate | [`evaluate`] (`evaluate/`: the f64 answers once, components, transfer, summary) | how a table is judged against f64 |
//! | check, regress | [`check`], [`regress`] | the device run against f64 (frames through `firmware_sim::device::run_frame`, the one device loop), the quantization baseline |
//! | reports | [`inspect`], [`metrics`], [`relight`], [`view`], [`web`] (the browser viewer), [`picture`], [`bench`](mod@bench), [`output`] | what is printed, drawn or exported (light maps, `.glb`) |
//! | files, limits | [`files`], [`limits`] | where outputs may go and how they are written (atomically); the limit of every size a user gives |
//! | command line | `src/bin/radiosity/` (`args.rs` every flag and its `--help`, `main.rs` runs the commands) | a flag or subcommand (the library takes plain options) |

pub mod bake;
pub mod bench;
pub mod check;
pub mod embree;
pub mod evaluate;
pub mod files;
pub mod formfactor;
pub mod hierarchy;
pub mod input;
pub mod inspect;
pub mod lighting;
pub mod limits;
pub mod mesh;
pub mod metrics;
pub mod montecarlo;
pub mod output;
pub mod patch;
pub mod picture;
pub mod pipeline;
pub mod raycast;
pub mod reference;
pub mod regress;
pub mod relight;
pub mod rgb;
pub mod rng;
pub mod scene;
pub mod text;
pub mod view;
pub mod web;
