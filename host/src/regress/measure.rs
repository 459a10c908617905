//! Measuring the tracked components of one scene and codec (through [`crate::check::check`]), and re-measuring
//! a whole baseline.

use std::collections::BTreeMap;
use std::path::Path;

use firmware_sim::sim::Arith;
use radiosity_core::FfCodec;

use super::{
    noise_multiplier, scene_files, Baseline, ComponentStats, Entry, RegressError, SceneSettings, Stat,
    CODECS, JITTER, TRACKED,
};
use crate::check::{check, CheckError, CheckOptions};
use crate::pipeline::prepare;
use crate::rng::SplitMix64;

/// Scales every pair's form factors by `1 + JITTER u` (see [`JITTER`]), `u` in `(-1, 1)` from the form factors'
/// generator seeded by `jitter` and the unordered pair, so `A_i F_ij = A_j F_ji` stays as it was.
pub fn jitter_form_factors(ff: &mut crate::patch::FormFactorMatrix, jitter: u64) {
    ff.map_values(|i, j, f| {
        let (lo, hi) = (i.min(j) as u64, i.max(j) as u64);
        let u = 2.0 * SplitMix64::for_stream(jitter, lo, hi).open_unit() - 1.0;
        f * (1.0 + JITTER * u)
    });
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

#[cfg(test)]
mod tests {
    use super::jitter_form_factors;
    use crate::patch::FormFactorMatrix;
    use crate::regress::{Stat, JITTER};

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
