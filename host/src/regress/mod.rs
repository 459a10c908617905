//! Quantization regression: the error components of every shipped scene and codec, measured and compared with
//! a checked-in baseline (`tests/baseline/quantization.json`).
//!
//! # What is measured
//! For every scene `scenes/*.obj` and each codec (16-bit [`FfCodec::FLOAT16`], 8-bit [`FfCodec::FLOAT8`]),
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
//! rounding-level change of the estimator (1e-15..1e-9 relative, measured on such changes) flips some of them
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

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use radiosity_core::FfCodec;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use firmware_sim::sim::Arith;

use crate::check::{check, CheckError, CheckOptions};
use crate::evaluate::{QUANTIZATION, SPARSIFICATION};
use crate::formfactor::FormFactorOptions;
use crate::pipeline::{prepare, PrepareOptions};
use crate::rng::SplitMix64;

/// Components the regression tracks, by name ([`crate::evaluate::Component::name`]).
pub const TRACKED: [&str; 4] = [SPARSIFICATION, QUANTIZATION, "arithmetic (f32)", "arithmetic (fixed)"];

/// Relative size of the form-factor jitter that measures the noise of deterministic components (module docs,
/// "Scenes without Monte Carlo noise"): `2^-30`, about 9.3e-10, the largest relative change seen from a
/// rounding-level estimator change (3.0e-9 on the slab) within a factor of a few.
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

/// How a scene is prepared for the regression (small, so the test is fast).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneSettings {
    /// One patch per OBJ face.
    pub no_subdivide: bool,
    /// Longest patch edge (`None`: the scene's TOML or the default).
    pub max_patch_edge: Option<f64>,
    /// Most patches (`None`: the scene's TOML or the default).
    pub max_patches: Option<usize>,
    /// Sample points per patch.
    pub samples: usize,
    /// Occlusion rays per pair.
    pub rays: usize,
}

impl Default for SceneSettings {
    fn default() -> Self {
        SceneSettings {
            no_subdivide: false,
            max_patch_edge: None,
            max_patches: Some(400),
            samples: 4,
            rays: 4,
        }
    }
}

impl SceneSettings {
    /// The pipeline options for seed `seed`.
    #[must_use]
    pub fn prepare_options(&self, seed: u64) -> PrepareOptions {
        PrepareOptions {
            no_subdivide: self.no_subdivide,
            max_patch_edge: self.max_patch_edge,
            max_patches: self.max_patches,
            form_factors: FormFactorOptions {
                samples_per_patch: self.samples,
                rays_per_pair: self.rays,
                seed,
                progress: false,
                ..FormFactorOptions::default()
            },
            verbose: false,
        }
    }
}

/// One metric of one component across seeds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stat {
    /// Value at each seed, in seed order.
    pub values: Vec<f64>,
    /// Mean over the seeds.
    pub mean: f64,
    /// Sample standard deviation over the seeds (the Monte Carlo noise), or, when every seed gave the same value,
    /// the root-mean-square deviation of [`Stat::jittered`] from it.
    pub noise: f64,
    /// Values at the form-factor jitters `1..=S` (seed 1), measured only when every seed gave the same value
    /// (module docs, "Scenes without Monte Carlo noise"); empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub jittered: Vec<f64>,
}

impl Stat {
    fn of(values: Vec<f64>) -> Stat {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = if values.len() > 1 {
            values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        Stat { values, mean, noise: var.sqrt(), jittered: Vec::new() }
    }

    /// Whether every seed gave the same value (no Monte Carlo noise to measure).
    fn deterministic(&self) -> bool {
        self.values.windows(2).all(|w| w[0] == w[1])
    }

    /// Takes the noise from jittered values (see [`Stat::jittered`]).
    fn with_jitter(mut self, jittered: Vec<f64>) -> Stat {
        let n = jittered.len().max(1) as f64;
        self.noise = (jittered.iter().map(|v| (v - self.mean) * (v - self.mean)).sum::<f64>() / n).sqrt();
        self.jittered = jittered;
        self
    }
}

/// Scales every pair's form factors by `1 + JITTER u` (see [`JITTER`]), `u` in `(-1, 1)` from the form factors'
/// generator seeded by `jitter` and the unordered pair, so `A_i F_ij = A_j F_ji` stays as it was.
pub fn jitter_form_factors(ff: &mut crate::patch::FormFactorMatrix, jitter: u64) {
    ff.map_values(|i, j, f| {
        let (lo, hi) = (i.min(j) as u64, i.max(j) as u64);
        let u = 2.0 * SplitMix64::for_stream(jitter, lo, hi).open_unit() - 1.0;
        f * (1.0 + JITTER * u)
    });
}

/// A tracked component's two metrics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ComponentStats {
    /// Area-weighted relative L2.
    pub rel_l2: Stat,
    /// Max per-patch relative error.
    pub max_rel: Stat,
}

/// The baseline of one scene and codec.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// Scene file name in the scenes folder (`cornell-box.obj`).
    pub scene: String,
    /// Form-factor code width (16 or 8).
    pub bits: u32,
    /// Codec name (for readers).
    pub codec: String,
    /// Patches the scene meshed into.
    pub patches: usize,
    /// Preparation settings.
    pub settings: SceneSettings,
    /// Tracked components by name (empty when the check fails, see `error`).
    pub components: BTreeMap<String, ComponentStats>,
    /// The check's error at the first seed, when the bake or check rejects this scene and codec (e.g. an 8-bit
    /// code that cannot hold a row's small entries): the regression then expects the same rejection.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The checked-in baseline file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Baseline {
    /// How to read and update this file.
    pub about: String,
    /// Seeds measured (`1..=seeds`).
    pub seeds: usize,
    /// Noise multiplier `k` for that many seeds (informative; recomputed when checking).
    pub k: f64,
    /// One entry per scene and codec.
    pub entries: Vec<Entry>,
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

/// The shipped scenes: `*.obj` file names in `dir`, sorted.
///
/// # Errors
/// [`RegressError::Io`] if the folder cannot be listed.
pub fn scene_files(dir: &Path) -> Result<Vec<String>, RegressError> {
    let io = |e: std::io::Error| RegressError::Io { path: dir.into(), message: e.to_string() };
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if path.extension().is_some_and(|e| e == "obj") {
            if let Some(name) = path.file_name().and_then(|n| n.to_str()) {
                names.push(name.to_string());
            }
        }
    }
    names.sort();
    Ok(names)
}

/// `(rel_l2, max_rel)` per tracked component name.
pub type Measured = BTreeMap<String, (f64, f64)>;

/// Measures the tracked components of one scene with one codec at one seed, its form factors jittered if
/// `jitter` is given ([`jitter_form_factors`]); returns the patch count and `(rel_l2, max_rel)` per tracked
/// component.
///
/// # Errors
/// [`RegressError::Check`] if preparing or checking fails.
pub fn measure(
    scene: &Path,
    settings: &SceneSettings,
    bits: u32,
    codec: Option<FfCodec>,
    seed: u64,
    jitter: Option<u64>,
) -> Result<(usize, Measured), RegressError> {
    let name = scene.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let wrap = |source: CheckError| RegressError::Check {
        scene: name.clone(),
        bits,
        seed,
        source: Box::new(source),
    };
    let po = settings.prepare_options(seed);
    let mut p = prepare(scene, &po).map_err(|e| wrap(e.into()))?;
    if let Some(j) = jitter {
        jitter_form_factors(&mut p.form_factors, j);
    }
    // Shooting with decoded rows converges to the shooting form `A_j F_ji / A_i` of the decoded table; an
    // entry may be bumped up by one code step (< 2^-M relative for a float code with M mantissa bits, core's
    // codec docs), so its row sums may exceed the original's by that much: allow it in the f64 solves (the
    // default 1e-4 alone makes every 8-bit bake of a closed scene fail).
    let c = match codec {
        Some(c) => c,
        None => crate::bake::codec_for_bits(bits).map_err(|e| wrap(e.into()))?,
    };
    let step = 2f64.powi(-i32::from(c.bits.saturating_sub(c.exponent_bits)));
    let options = CheckOptions {
        bits,
        codec,
        ff_factor: 1,
        arith: Arith::ALL.to_vec(),
        row_sum_tolerance: crate::bake::DEFAULT_ROW_SUM_TOLERANCE + step,
        ..CheckOptions::default()
    };
    let report = check(&p, &po, &options).map_err(wrap)?;
    let mut out = BTreeMap::new();
    for c in report.components {
        if TRACKED.contains(&c.name.as_str()) {
            out.insert(c.name, (c.error.rel_l2, c.error.max_rel));
        }
    }
    Ok((p.patches.len(), out))
}

/// Re-measures every scene in `scenes` with every codec at seeds `1..=seeds`. Settings of scenes already in
/// `old` are kept; new scenes get [`SceneSettings::default`].
///
/// # Errors
/// [`RegressError`] if a scene fails or `seeds` is out of range.
pub fn update(old: Option<&Baseline>, scenes: &Path, seeds: usize) -> Result<Baseline, RegressError> {
    let k = noise_multiplier(seeds).ok_or(RegressError::Seeds(seeds))?;
    let mut entries = Vec::new();
    for name in scene_files(scenes)? {
        for bits in CODECS {
            let settings = old
                .and_then(|b| b.entries.iter().find(|e| e.scene == name))
                .map_or_else(SceneSettings::default, |e| e.settings.clone());
            let mut patches = 0;
            let mut values: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
            let mut error = None;
            for seed in 1..=seeds as u64 {
                let (n, m) = match measure(&scenes.join(&name), &settings, bits, None, seed, None) {
                    Ok(r) => r,
                    Err(RegressError::Check { source, .. }) if seed == 1 => {
                        error = Some(source.to_string());
                        break;
                    }
                    Err(e) => return Err(e),
                };
                patches = n;
                for (c, (l2, mx)) in m {
                    let v = values.entry(c).or_default();
                    v.0.push(l2);
                    v.1.push(mx);
                }
            }
            let mut components: BTreeMap<String, ComponentStats> = values
                .into_iter()
                .map(|(c, (l2, mx))| (c, ComponentStats { rel_l2: Stat::of(l2), max_rel: Stat::of(mx) }))
                .collect();
            // Components without Monte Carlo noise: their noise from jittered form factors (module docs).
            if components.values().any(|c| c.rel_l2.deterministic() || c.max_rel.deterministic()) {
                let mut jittered: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
                for j in 1..=seeds as u64 {
                    // A jitter the bake rejects (a borderline codec) is left out of the noise.
                    let m = match measure(&scenes.join(&name), &settings, bits, None, 1, Some(j)) {
                        Ok((_, m)) => m,
                        Err(RegressError::Check { .. }) => continue,
                        Err(e) => return Err(e),
                    };
                    for (c, (l2, mx)) in m {
                        let v = jittered.entry(c).or_default();
                        v.0.push(l2);
                        v.1.push(mx);
                    }
                }
                for (c, stats) in &mut components {
                    let Some((l2, mx)) = jittered.remove(c) else { continue };
                    if stats.rel_l2.deterministic() {
                        stats.rel_l2 = stats.rel_l2.clone().with_jitter(l2);
                    }
                    if stats.max_rel.deterministic() {
                        stats.max_rel = stats.max_rel.clone().with_jitter(mx);
                    }
                }
            }
            let codec = crate::bake::codec_for_bits(bits).map(|c| c.to_string()).unwrap_or_default();
            entries.push(Entry { scene: name.clone(), bits, codec, patches, settings, components, error });
        }
    }
    Ok(Baseline {
        about: "Quantization regression baseline (host/src/regress.rs). Regenerate with `radiosity regress \
                --update` from the repository root; check with `radiosity regress`."
            .into(),
        seeds,
        k,
        entries,
    })
}

/// Reads a baseline file.
///
/// # Errors
/// [`RegressError::Io`] or [`RegressError::BadBaseline`].
pub fn read_baseline(path: &Path) -> Result<Baseline, RegressError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| RegressError::Io { path: path.into(), message: e.to_string() })?;
    serde_json::from_str(&text)
        .map_err(|e| RegressError::BadBaseline { path: path.into(), message: e.to_string() })
}

/// Writes a baseline file (pretty JSON, trailing newline), creating its folder.
///
/// # Errors
/// [`RegressError::Io`].
pub fn write_baseline(path: &Path, baseline: &Baseline) -> Result<(), RegressError> {
    let io = |e: std::io::Error| RegressError::Io { path: path.into(), message: e.to_string() };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let mut text = serde_json::to_string_pretty(baseline)
        .map_err(|e| RegressError::Io { path: path.into(), message: e.to_string() })?;
    text.push('\n');
    std::fs::write(path, text).map_err(io)
}

/// One compared value.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Row {
    /// Scene file.
    pub scene: String,
    /// Code width of the baseline entry.
    pub bits: u32,
    /// Codec actually used (differs from the baseline's when degraded on purpose).
    pub codec: String,
    /// Component name.
    pub component: String,
    /// `rel_l2` or `max_rel`.
    pub metric: &'static str,
    /// Baseline mean (`None`: not in the baseline).
    pub baseline: Option<f64>,
    /// Baseline noise.
    pub noise: Option<f64>,
    /// The limit `mean + k noise + floor` (check) or `None` (update).
    pub limit: Option<f64>,
    /// The new value (check: at the first seed; update: the new mean).
    pub value: Option<f64>,
    /// New noise (update only).
    pub new_noise: Option<f64>,
    /// Whether the value is within its limit (always true on update).
    pub ok: bool,
}

/// Rows of a check or an update.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RegressReport {
    /// `check` or `update`.
    pub mode: &'static str,
    /// The noise multiplier `k`.
    pub k: f64,
    /// Every compared value.
    pub rows: Vec<Row>,
    /// Problems that are not a single value (scene not in the baseline, baseline scene no longer shipped).
    pub problems: Vec<String>,
}

impl RegressReport {
    /// Whether every value is within its limit and nothing is missing.
    #[must_use]
    pub fn passed(&self) -> bool {
        self.problems.is_empty() && self.rows.iter().all(|r| r.ok)
    }

    /// The rows over their limits.
    #[must_use]
    pub fn failures(&self) -> Vec<&Row> {
        self.rows.iter().filter(|r| !r.ok).collect()
    }
}

/// What [`check_baseline`] runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CheckSelection {
    /// Only this scene file (e.g. `cornell-box.obj`).
    pub scene: Option<String>,
    /// Only entries of this code width.
    pub bits: Option<u32>,
    /// Bake with this codec in place of the entry's (to degrade it on purpose).
    pub codec: Option<FfCodec>,
}

fn error_row(entry: &Entry, codec: &str, now: Option<String>, ok: bool) -> Row {
    Row {
        scene: entry.scene.clone(),
        bits: entry.bits,
        codec: codec.into(),
        component: format!("rejected: {}", now.unwrap_or_default()),
        metric: "error",
        baseline: None,
        noise: None,
        limit: None,
        value: None,
        new_noise: None,
        ok,
    }
}

/// Recomputes every selected baseline entry at the first seed and compares each tracked component with its
/// limit (see the module docs). Shipped scenes missing from the baseline, and baseline scenes no longer in
/// `scenes`, are problems (the check fails until `radiosity regress --update`).
///
/// # Errors
/// [`RegressError`] if a scene cannot be checked.
pub fn check_baseline(
    baseline: &Baseline,
    scenes: &Path,
    selection: &CheckSelection,
) -> Result<RegressReport, RegressError> {
    let k = noise_multiplier(baseline.seeds).ok_or(RegressError::Seeds(baseline.seeds))?;
    let shipped = scene_files(scenes)?;
    let mut problems = Vec::new();
    if selection.scene.is_none() {
        for name in &shipped {
            for bits in CODECS {
                if !baseline.entries.iter().any(|e| &e.scene == name && e.bits == bits) {
                    problems.push(format!(
                        "{name} ({bits}-bit) is shipped but not in the baseline: run `radiosity regress --update`"
                    ));
                }
            }
        }
    }
    let mut rows = Vec::new();
    for entry in &baseline.entries {
        if selection.scene.as_ref().is_some_and(|s| s != &entry.scene)
            || selection.bits.is_some_and(|b| b != entry.bits)
        {
            continue;
        }
        if !shipped.contains(&entry.scene) {
            problems.push(format!(
                "{} is in the baseline but not in {}: run `radiosity regress --update`",
                entry.scene,
                scenes.display()
            ));
            continue;
        }
        let codec = match selection.codec {
            Some(c) => c.to_string(),
            None => entry.codec.clone(),
        };
        let measured =
            measure(&scenes.join(&entry.scene), &entry.settings, entry.bits, selection.codec, 1, None);
        let (n, values) = match (measured, &entry.error) {
            (Ok(v), None) => v,
            (Err(RegressError::Check { source, .. }), Some(_)) => {
                rows.push(error_row(entry, &codec, Some(source.to_string()), true));
                continue;
            }
            (Ok(_), Some(_)) => {
                problems.push(format!(
                    "{} ({}-bit) was rejected in the baseline and checks now: run `radiosity regress --update`",
                    entry.scene, entry.bits
                ));
                continue;
            }
            (Err(RegressError::Check { source, .. }), None) => {
                rows.push(error_row(entry, &codec, Some(source.to_string()), false));
                continue;
            }
            (Err(e), _) => return Err(e),
        };
        let floor = 8.0 * n as f64 * f64::EPSILON;
        for name in TRACKED {
            let old = entry.components.get(name);
            let new = values.get(name);
            let stats = [("rel_l2", old.map(|s| &s.rel_l2)), ("max_rel", old.map(|s| &s.max_rel))];
            for (i, (metric, stat)) in stats.into_iter().enumerate() {
                let value = new.map(|v| if i == 0 { v.0 } else { v.1 });
                let limit = stat.map(|s| s.mean + k * s.noise + floor);
                let ok = match (value, limit) {
                    (Some(v), Some(l)) => v <= l,
                    (None, None) => true,
                    _ => false,
                };
                rows.push(Row {
                    scene: entry.scene.clone(),
                    bits: entry.bits,
                    codec: codec.clone(),
                    component: name.into(),
                    metric,
                    baseline: stat.map(|s| s.mean),
                    noise: stat.map(|s| s.noise),
                    limit,
                    value,
                    new_noise: None,
                    ok,
                });
            }
        }
    }
    Ok(RegressReport { mode: "check", k, rows, problems })
}

/// Old and new baselines side by side (every value of `new`, with the matching one of `old` if any).
#[must_use]
pub fn compare_baselines(old: Option<&Baseline>, new: &Baseline) -> RegressReport {
    let mut rows = Vec::new();
    for e in &new.entries {
        let o = old.and_then(|b| b.entries.iter().find(|o| o.scene == e.scene && o.bits == e.bits));
        if let Some(err) = &e.error {
            rows.push(error_row(e, &e.codec, Some(err.clone()), true));
        }
        for (name, stats) in &e.components {
            let os = o.and_then(|o| o.components.get(name));
            for (metric, ns, old_stat) in [
                ("rel_l2", &stats.rel_l2, os.map(|s| &s.rel_l2)),
                ("max_rel", &stats.max_rel, os.map(|s| &s.max_rel)),
            ] {
                rows.push(Row {
                    scene: e.scene.clone(),
                    bits: e.bits,
                    codec: e.codec.clone(),
                    component: name.clone(),
                    metric,
                    baseline: old_stat.map(|s| s.mean),
                    noise: old_stat.map(|s| s.noise),
                    limit: None,
                    value: Some(ns.mean),
                    new_noise: Some(ns.noise),
                    ok: true,
                });
            }
        }
    }
    RegressReport { mode: "update", k: new.k, rows, problems: Vec::new() }
}

fn opt(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{v:.3e}"))
}

impl fmt::Display for RegressReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.mode == "update" {
            writeln!(f, "baseline update (old and new: mean and noise over the seeds), k = {:.3}", self.k)?;
            writeln!(
                f,
                "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}",
                "scene", "codec", "component", "metric", "old mean", "old noise", "new mean", "new noise"
            )?;
            for r in &self.rows {
                writeln!(
                    f,
                    "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}",
                    r.scene,
                    r.codec,
                    r.component,
                    r.metric,
                    opt(r.baseline),
                    opt(r.noise),
                    opt(r.value),
                    opt(r.new_noise)
                )?;
            }
        } else {
            writeln!(f, "regression check: limit = mean + k noise + 8 n eps, k = {:.3}", self.k)?;
            writeln!(
                f,
                "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}  status",
                "scene", "codec", "component", "metric", "baseline", "noise", "limit", "now"
            )?;
            for r in &self.rows {
                writeln!(
                    f,
                    "{:<28} {:<9} {:<20} {:<8} {:>10} {:>10} {:>10} {:>10}  {}",
                    r.scene,
                    r.codec,
                    r.component,
                    r.metric,
                    opt(r.baseline),
                    opt(r.noise),
                    opt(r.limit),
                    opt(r.value),
                    if r.ok { "ok" } else { "FAIL" }
                )?;
            }
            let failed = self.failures().len();
            writeln!(f, "{} values, {} over their limit", self.rows.len(), failed)?;
        }
        for p in &self.problems {
            writeln!(f, "problem: {p}")?;
        }
        Ok(())
    }
}

/// What `radiosity regress` does (its command-line options are in the binary).
#[derive(Clone, Debug)]
pub struct RegressOptions {
    /// Re-measure everything and write the baseline (prints old and new values side by side).
    pub update: bool,
    /// The baseline file.
    pub baseline: PathBuf,
    /// The folder of shipped scenes (`*.obj`).
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

#[cfg(test)]
mod tests {
    use super::{jitter_form_factors, Stat, JITTER};
    use crate::patch::FormFactorMatrix;

    /// A reciprocal 3-patch matrix (areas 1, 2, 4).
    fn matrix() -> FormFactorMatrix {
        // A_0 F_01 = 0.2 = A_1 F_10, A_0 F_02 = 0.4 = A_2 F_20, A_1 F_12 = 0.6 = A_2 F_21.
        FormFactorMatrix::new(
            3,
            vec![0, 2, 4, 6],
            vec![1, 2, 0, 2, 0, 1],
            vec![0.2, 0.4, 0.1, 0.3, 0.1, 0.15],
        )
        .unwrap()
    }

    #[test]
    fn jitter_is_small_reciprocal_and_seeded() {
        let area = [1.0, 2.0, 4.0];
        let base = matrix();
        let mut a = matrix();
        jitter_form_factors(&mut a, 1);
        let mut b = matrix();
        jitter_form_factors(&mut b, 1);
        let mut c = matrix();
        jitter_form_factors(&mut c, 2);
        assert_eq!(a, b, "the same jitter seed gives the same matrix");
        assert_ne!(a.values(), c.values(), "another seed another matrix");
        assert_ne!(a.values(), base.values(), "the jitter changes the entries");
        let get = |m: &FormFactorMatrix, i: usize, j: usize| m.get(i, j);
        for i in 0..3 {
            for (j, f) in a.row(i) {
                let f0 = get(&base, i, j);
                assert!((f / f0 - 1.0).abs() <= JITTER * (1.0 + 1e-6), "({i}, {j}): {f} vs {f0}");
                let (g, h) = (area[i] * f, area[j] * get(&a, j, i));
                assert!((g - h).abs() <= 4.0 * f64::EPSILON * g, "({i}, {j}) not reciprocal: {g} vs {h}");
            }
        }
    }

    #[test]
    fn jittered_noise_is_the_rms_deviation_from_the_unjittered_value() {
        let s = Stat::of(vec![2.0; 5]);
        assert!(s.deterministic() && s.noise == 0.0);
        let j = s.with_jitter(vec![2.0, 2.0, 2.0, 4.0, 0.0]);
        assert!((j.noise - (8.0f64 / 5.0).sqrt()).abs() < 1e-15, "{}", j.noise);
        assert!(!Stat::of(vec![1.0, 2.0]).deterministic());
    }
}
