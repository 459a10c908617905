//! `radiosity-host`: the workstation side of the radiosity toolkit.
//!
//! Scene loading, meshing into patches, form factors with occlusion rays (`raycast`: Embree in production, a
//! pure-Rust BVH for tests and cross-checks), the f64 reference solve, table writing, checks and reports. The
//! physics conventions are those of `radiosity-core`; `rng` is the one random number generator.

pub mod bake;
pub mod bench;
pub mod check;
pub mod embree;
pub mod evaluate;
pub mod formfactor;
pub mod input;
pub mod inspect;
pub mod lighting;
pub mod mesh;
pub mod metrics;
pub mod output;
pub mod patch;
pub mod picture;
pub mod pipeline;
pub mod raycast;
pub mod reference;
pub mod regress;
pub mod relight;
pub mod rng;
pub mod scene;
pub mod view;
