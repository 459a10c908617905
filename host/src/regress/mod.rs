//! Quantization regression: the error components of every shipped scene and codec, measured and compared with
//! a checked-in baseline (`tests/baseline/quantization.json`).
//!
//! # What is measured
//! For every scene `scenes/*.obj`, `*.gltf` and `*.glb` and each codec (16-bit [`radiosity_core::FfCodec::FLOAT16`], 8-bit [`radiosity_core::FfCodec::FLOAT8`]),
//! [`crate::check::check`] runs with the scene's regression settings ([`SceneSettings`]: meshing, samples and
//! rays per pair, kept in the baseline so the test stays fast) and the default check options otherwise (solver
//! run to convergence, so iteration truncation is identically zero and not tracked). Tracked components
//! ([`TRACKED`]): sparsification, quantization, arithmetic (f32), arithmetic (fixed); metrics: area-weighted
//! relative L2 and max per-patch relative error ([`crate::metrics`]).
//!
//! # Noise and the limit
//! The components depend on the Monte Carlo form-factor estimate. [`update`] measures every component at `S`
//! seeds (`1..=S`, default [`DEFAULT_SEEDS`]) and stores the values, their mean `m` and sample standard
//! deviation `s` (the noise). [`check_baseline`] recomputes each component once, at the first seed, and fails
//! when it exceeds
//!
//! `limit = m + k s + floor`, with `k = t(0.995, S - 1) * sqrt(1 + 1/S)`:
//!
//! the upper end of a one-sided 99.5 % prediction interval for one new observation from the distribution the
//! `S` seeds sampled (Student's t, because `s` is itself estimated from `S` values; e.g. Montgomery & Runger,
//! *Applied Statistics and Probability for Engineers*, prediction intervals). With `S = 5`, `k = 4.604 *
//! sqrt(1.2) = 5.04`. `floor = 8 n eps` (`n` patches, `eps` = f64 machine epsilon) covers components that are
//! exactly zero at every seed (a uniform scene that sparsification does not touch): an f64 solve of `n`
//! unknowns agrees with another to about `n eps`, the faer-style `8 n eps` bound. A degraded codec moves the
//! quantization component by far more than that (see the tests in `host/tests/check.rs`).
//!
//! # Scenes without Monte Carlo noise
//! A scene where nothing is occluded gives the same form factors at every seed, so `s = 0` and only the floor
//! is left; yet its components are not smooth in the form factors: sparsification and the codec's rounding make
//! discrete choices (which entry to drop, which code to bump), and in a symmetric scene many entries tie. A
//! rounding-level change of the estimator (a different summation order, a different thread count) flips some of them
//! and moves a component by percent, far above `8 n eps`. So where every seed gave the same value, [`update`]
//! measures the component again at `S` jitters ([`JITTER`]: every pair's `A_i F_ij` scaled by `1 + JITTER u`,
//! `u` uniform in `(-1, 1)`, the same for both directions so the matrix stays reciprocal) and takes as the noise
//! the root-mean-square deviation of the jittered values from the unjittered one ([`Stat::jittered`]). The
//! check itself never jitters.
//!
//! # Re-baselining
//! `radiosity regress --update` re-measures everything (keeping each scene's settings, giving new scenes the
//! defaults [`SceneSettings::default`]), writes the baseline and prints old and new values side by side;
//! `radiosity regress` checks and prints the same table with the limits.

mod baseline;
mod compare;
mod measure;
mod report;

use std::path::PathBuf;

use thiserror::Error;

pub use baseline::{
    read_baseline, scene_files, write_baseline, Baseline, ComponentStats, Entry, SceneSettings, Stat,
};
pub use compare::{check_baseline, compare_baselines, CheckSelection};
pub use measure::{jitter_form_factors, measure, update, Measured};
pub use report::{RegressReport, Row};

use crate::check::CheckError;
use crate::evaluate::{QUANTIZATION, SPARSIFICATION};

/// Components the regression tracks, by name ([`crate::evaluate::Component::name`]).
pub const TRACKED: [&str; 4] = [SPARSIFICATION, QUANTIZATION, "arithmetic (f32)", "arithmetic (fixed)"];

/// Relative size of the form-factor jitter that measures the noise of deterministic components (module docs,
/// "Scenes without Monte Carlo noise"): `2^-30`, within a factor of a few of the relative change a
/// rounding-level change of the estimator makes.
pub const JITTER: f64 = 1.0 / (1u64 << 30) as f64;

/// Seeds measured by [`update`] unless told otherwise.
pub const DEFAULT_SEEDS: usize = 5;

/// The codecs measured: the two the bake ships, by code width.
pub const CODECS: [u32; 2] = [16, 8];

/// One-sided 99.5 % quantile of Student's t with `dof` degrees of freedom (tables, e.g. NIST/SEMATECH
/// e-Handbook 1.3.6.7.2); `None` outside `1..=10`.
#[must_use]
pub fn student_t_995(dof: usize) -> Option<f64> {
    const T: [f64; 10] = [63.657, 9.925, 5.841, 4.604, 4.032, 3.707, 3.499, 3.355, 3.250, 3.169];
    dof.checked_sub(1).and_then(|i| T.get(i)).copied()
}

/// The noise multiplier `k = t(0.995, S - 1) * sqrt(1 + 1/S)` for `S` seeds (see the module docs).
#[must_use]
pub fn noise_multiplier(seeds: usize) -> Option<f64> {
    student_t_995(seeds.checked_sub(1)?).map(|t| t * (1.0 + 1.0 / seeds as f64).sqrt())
}

/// Why the regression could not run.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RegressError {
    /// A check failed.
    #[error("{scene} ({bits}-bit, seed {seed}): {source}")]
    Check {
        /// Scene file.
        scene: String,
        /// Code width.
        bits: u32,
        /// Seed.
        seed: u64,
        /// The check's error (boxed: it is large).
        source: Box<CheckError>,
    },
    /// The scenes folder or the baseline could not be read or written.
    #[error("{path}: {message}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The baseline is not valid JSON of the expected shape.
    #[error("baseline {path}: {message}")]
    BadBaseline {
        /// The baseline file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// Too few or too many seeds for the noise estimate.
    #[error("{0} seeds: the noise estimate needs 2..=11")]
    Seeds(usize),
}

/// What `radiosity regress` does (its command-line options are in the binary).
#[derive(Clone, Debug)]
pub struct RegressOptions {
    /// Re-measure everything and write the baseline (prints old and new values side by side).
    pub update: bool,
    /// The baseline file.
    pub baseline: PathBuf,
    /// The folder of shipped scenes (`*.obj`, `*.gltf`, `*.glb`).
    pub scenes: PathBuf,
    /// Seeds measured by `--update` (the noise estimate; 2..=11).
    pub seeds: usize,
    /// Only this scene file (check only), e.g. `cornell-box.obj`.
    pub scene: Option<String>,
}

/// Runs `radiosity regress` (check, or update with `--update`) and returns its report.
///
/// # Errors
/// [`RegressError`]; a check whose values exceed their limits is not an error here (see
/// [`RegressReport::passed`]).
pub fn run(args: &RegressOptions) -> Result<RegressReport, RegressError> {
    if args.update {
        let old = if args.baseline.exists() { Some(read_baseline(&args.baseline)?) } else { None };
        let new = update(old.as_ref(), &args.scenes, args.seeds)?;
        write_baseline(&args.baseline, &new)?;
        Ok(compare_baselines(old.as_ref(), &new))
    } else {
        let baseline = read_baseline(&args.baseline)?;
        let selection = CheckSelection { scene: args.scene.clone(), ..CheckSelection::default() };
        check_baseline(&baseline, &args.scenes, &selection)
    }
}
