//! The path tracer proper: the scene as the paths see it ([`TraceScene`]) and one batch of paths from one face
//! ([`TraceScene::trace_batch`]), advanced together one bounce at a time so the shadow rays of a bounce go to the
//! caster as one batch.

use glam::DVec3;

use super::MonteCarloError;
use crate::formfactor::{cosine_direction, grid, tangent_frame, PolygonSampler};
use crate::lighting::PatchLighting;
use crate::patch::Patch;
use crate::raycast::{Ray, RayCaster};
use crate::rgb::{self, Rgb};
use crate::rng::SplitMix64;

/// Mixed into the seed of the path streams (keyed by face and sample index).
const PATH_STREAM: u64 = 0x4D43_5041_5448_0000;
/// Mixed into the seed of the strata streams (keyed by face and batch index).
const STRATA_STREAM: u64 = 0x4D43_5354_5241_0000;
/// Mixed into the seed of the path streams of probes (keyed by probe and sample index).
const PROBE_STREAM: u64 = 0x4D43_5052_4F42_0000;

/// One face as the estimator samples it: its polygons (patches of the unsubdivided mesh) with their cumulative
/// area fractions.
#[derive(Clone, Debug)]
struct FaceSampler {
    /// `(patch, sampler, cumulative area fraction up to and including this polygon)`.
    polygons: Vec<(usize, PolygonSampler, f64)>,
}

impl FaceSampler {
    /// The point and patch for `(s, t)` in the open unit square: `s` picks the polygon by area and is rescaled
    /// within it, so the map stays area-preserving and strata in the square stay strata on the face.
    fn point(&self, s: f64, t: f64) -> (DVec3, usize) {
        let mut lower = 0.0;
        for (k, (patch, sampler, upper)) in self.polygons.iter().enumerate() {
            if s < *upper || k + 1 == self.polygons.len() {
                let u = ((s - lower) / (upper - lower)).clamp(0.0, 1.0);
                return (sampler.point(u, t), *patch);
            }
            lower = *upper;
        }
        unreachable!("a face has at least one polygon")
    }
}

/// Everything a path needs to know about the scene, built once.
#[derive(Debug)]
pub(super) struct TraceScene<'a> {
    patches: &'a [Patch],
    /// Reflectance per patch.
    rho: Vec<Rgb>,
    /// Emission per patch at the default intensities.
    emission: Vec<Rgb>,
    /// The patch of every occluder triangle, in [`crate::formfactor::occluder_mesh`]'s order.
    triangle_patch: Vec<u32>,
    /// One sampler per face.
    faces: Vec<FaceSampler>,
    /// One sampler per patch (emitters only are ever sampled).
    samplers: Vec<PolygonSampler>,
    /// Emitting patches with their cumulative selection probabilities (proportional to area times the largest
    /// channel of the emission).
    emitters: Vec<(usize, f64)>,
    /// Area density of the light sampling on each patch, `P_k / A_k` (0 on patches that do not emit).
    light_density: Vec<f64>,
    /// How far ray origins are lifted off their surface (the caster's offset).
    lift: f64,
}

/// Sums of one batch of paths from one face: the sample count, the mean irradiance estimate and the sum of
/// squared deviations from it (per channel), for an exact merge in a fixed order ([`Moments::merge`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Moments {
    /// Samples.
    pub count: u64,
    /// Mean of the samples.
    pub mean: Rgb,
    /// Sum of squared deviations from the mean.
    pub m2: Rgb,
    /// Rays cast (shadow and bounce rays).
    pub rays: u64,
}

impl Moments {
    /// Adds one sample (Welford's update).
    pub fn push_sample(&mut self, x: Rgb) {
        self.count += 1;
        let delta = x - self.mean;
        self.mean += delta / self.count as f64;
        self.m2 += delta * (x - self.mean);
    }

    /// The moments of both sets of samples (Chan, Golub and LeVeque's pairwise update, 1979).
    pub fn merge(self, other: Moments) -> Moments {
        if other.count == 0 {
            return Moments { rays: self.rays + other.rays, ..self };
        }
        if self.count == 0 {
            return Moments { rays: self.rays + other.rays, ..other };
        }
        let count = self.count + other.count;
        let delta = other.mean - self.mean;
        let weight = other.count as f64 / count as f64;
        Moments {
            count,
            mean: self.mean + delta * weight,
            m2: self.m2 + other.m2 + delta * delta * (self.count as f64 * weight),
            rays: self.rays + other.rays,
        }
    }

    /// Standard error of the mean per channel, `sqrt(s^2 / n)` with the unbiased sample variance `s^2`; 0 below
    /// two samples.
    pub fn standard_error(&self) -> Rgb {
        if self.count < 2 {
            return Rgb::ZERO;
        }
        let n = self.count as f64;
        (self.m2 / ((n - 1.0) * n)).max(Rgb::ZERO).map(f64::sqrt)
    }
}

/// One path in flight.
struct Path {
    point: DVec3,
    normal: DVec3,
    patch: usize,
    /// Product of the reflectances met so far, divided by the Russian-roulette survival probabilities.
    throughput: Rgb,
    /// The irradiance estimate so far.
    sum: Rgb,
    rng: SplitMix64,
}

impl<'a> TraceScene<'a> {
    /// The scene of `patches` (the unsubdivided mesh of `face_count` faces) with their `lighting`; rays are
    /// lifted off surfaces by `lift` (the caster's offset).
    pub fn new(patches: &'a [Patch], lighting: &PatchLighting, face_count: usize, lift: f64) -> Self {
        let emission = lighting.default_emission();
        let mut triangle_patch = Vec::new();
        for (k, p) in patches.iter().enumerate() {
            triangle_patch.extend(std::iter::repeat_n(k as u32, p.vertices.len().saturating_sub(2)));
        }
        let mut faces: Vec<Vec<(usize, f64)>> = vec![Vec::new(); face_count];
        for (k, p) in patches.iter().enumerate() {
            faces[p.face].push((k, p.area));
        }
        let faces = faces
            .into_iter()
            .map(|polygons| {
                let total: f64 = polygons.iter().map(|(_, a)| a).sum();
                let mut cumulative = 0.0;
                let polygons = polygons
                    .into_iter()
                    .map(|(k, a)| {
                        cumulative += a / total;
                        (k, PolygonSampler::new(&patches[k].vertices), cumulative)
                    })
                    .collect();
                FaceSampler { polygons }
            })
            .collect();
        let weights: Vec<f64> =
            patches.iter().zip(&emission).map(|(p, e)| p.area * rgb::max_channel(*e).max(0.0)).collect();
        let total: f64 = weights.iter().sum();
        let mut emitters = Vec::new();
        let mut light_density = vec![0.0; patches.len()];
        let mut cumulative = 0.0;
        for (k, &w) in weights.iter().enumerate() {
            if w > 0.0 {
                cumulative += w / total;
                emitters.push((k, cumulative));
                light_density[k] = w / total / patches[k].area;
            }
        }
        TraceScene {
            patches,
            rho: lighting.rho.clone(),
            emission,
            triangle_patch,
            faces,
            samplers: patches.iter().map(|p| PolygonSampler::new(&p.vertices)).collect(),
            emitters,
            light_density,
            lift,
        }
    }

    /// Reflectance of patch `k`.
    pub fn rho(&self, k: usize) -> Rgb {
        self.rho[k]
    }

    /// Emission of patch `k` at the default intensities.
    pub fn emission(&self, k: usize) -> Rgb {
        self.emission[k]
    }

    /// A point of `k`'s surface lifted off it along its normal (see the module docs of [`super`]).
    fn lifted(&self, point: DVec3, normal: DVec3) -> glam::Vec3 {
        (point + normal * self.lift).as_vec3()
    }

    /// The emitter that `u` in `[0, 1)` selects.
    fn emitter(&self, u: f64) -> usize {
        let k = self.emitters.partition_point(|&(_, c)| c <= u).min(self.emitters.len() - 1);
        self.emitters[k].0
    }

    /// Traces the samples `first..first + count` of `face` (one stratified batch, `batch` its index) and returns
    /// the moments of their irradiance estimates.
    ///
    /// # Errors
    /// [`MonteCarloError::CasterMismatch`] if the caster reports a triangle the occluder mesh does not have.
    pub fn trace_batch<C: RayCaster + ?Sized>(
        &self,
        caster: &C,
        seed: u64,
        face: usize,
        batch: u64,
        first: u64,
        count: usize,
    ) -> Result<Moments, MonteCarloError> {
        // Strata: a jittered a x b grid over the face's unit square, its cells in random order, the first
        // `count` of them used (all of them for a full batch). Every sample is uniform on the face whichever
        // cells are used, so a partial batch is unbiased too.
        let (a, b) = grid(count);
        let mut cells: Vec<usize> = (0..a * b).collect();
        SplitMix64::for_stream(seed ^ STRATA_STREAM, face as u64, batch).shuffle(&mut cells);
        let paths: Vec<Path> = (0..count)
            .map(|k| {
                let mut rng = SplitMix64::for_stream(seed ^ PATH_STREAM, face as u64, first + k as u64);
                let cell = cells[k];
                let s = ((cell % a) as f64 + rng.open_unit()) / a as f64;
                let t = ((cell / a) as f64 + rng.open_unit()) / b as f64;
                let (point, patch) = self.faces[face].point(s.min(1.0), t.min(1.0));
                let normal = self.patches[patch].normal;
                Path { point, normal, patch, throughput: Rgb::ONE, sum: Rgb::ZERO, rng }
            })
            .collect();
        self.trace(caster, paths)
    }

    /// Traces the samples `first..first + count` of probe number `probe`: paths from `point`, a point of
    /// `patch` (its surface), and returns the moments of their irradiance estimates.
    ///
    /// # Errors
    /// [`MonteCarloError::CasterMismatch`] if the caster reports a triangle the occluder mesh does not have.
    #[allow(clippy::too_many_arguments)] // the probe's identity, its place and its share of the samples
    pub fn trace_probe<C: RayCaster + ?Sized>(
        &self,
        caster: &C,
        seed: u64,
        probe: usize,
        point: DVec3,
        patch: usize,
        first: u64,
        count: usize,
    ) -> Result<Moments, MonteCarloError> {
        let normal = self.patches[patch].normal;
        let paths = (0..count)
            .map(|k| {
                let rng = SplitMix64::for_stream(seed ^ PROBE_STREAM, probe as u64, first + k as u64);
                Path { point, normal, patch, throughput: Rgb::ONE, sum: Rgb::ZERO, rng }
            })
            .collect();
        self.trace(caster, paths)
    }

    /// Runs `paths` to their ends and returns the moments of their irradiance estimates, in path order.
    fn trace<C: RayCaster + ?Sized>(
        &self,
        caster: &C,
        mut paths: Vec<Path>,
    ) -> Result<Moments, MonteCarloError> {
        let count = paths.len();
        let mut finished = vec![Rgb::ZERO; count];
        let mut index: Vec<usize> = (0..count).collect();
        let mut rays = 0u64;
        let mut shadow_rays = Vec::with_capacity(count);
        let mut shadow_paths = Vec::with_capacity(count);
        let mut shadow_values = Vec::with_capacity(count);
        let mut occluded = Vec::with_capacity(count);
        while !paths.is_empty() {
            // Next-event estimation: one point on an emitter per path, weighted by the balance heuristic against
            // the cosine-distributed bounce (which may hit the same emitter; see the module docs).
            shadow_rays.clear();
            shadow_paths.clear();
            shadow_values.clear();
            for (p, path) in paths.iter_mut().enumerate() {
                if self.emitters.is_empty() {
                    break;
                }
                let k = self.emitter(path.rng.unit());
                let (s, t) = (path.rng.open_unit().min(1.0), path.rng.open_unit().min(1.0));
                if k == path.patch {
                    continue;
                }
                let y = self.samplers[k].point(s, t);
                let d = y - path.point;
                let r2 = d.length_squared();
                let r = r2.sqrt();
                let (cos_x, cos_y) = (path.normal.dot(d) / r, -self.patches[k].normal.dot(d) / r);
                if !(cos_x > 0.0 && cos_y > 0.0) {
                    continue;
                }
                let light = self.light_density[k] * r2 / cos_y;
                let cosine = cos_x / std::f64::consts::PI;
                let value = path.throughput * self.emission[k] * (cosine / (light + cosine));
                let from = self.lifted(path.point, path.normal);
                let to = self.lifted(y, self.patches[k].normal);
                shadow_rays.push(Ray::new(from, to - from, 0.0, 1.0));
                shadow_paths.push(p);
                shadow_values.push(value);
            }
            occluded.clear();
            occluded.resize(shadow_rays.len(), false);
            caster.occluded_many(&shadow_rays, &mut occluded);
            rays += shadow_rays.len() as u64;
            for ((&p, &value), &blocked) in shadow_paths.iter().zip(&shadow_values).zip(&occluded) {
                if !blocked {
                    paths[p].sum += value;
                }
            }
            // The bounce: a cosine-distributed direction; emission found there gets the bounce's share of the
            // balance heuristic, then the path continues from there with its reflectance, or stops.
            let mut k = 0;
            while k < paths.len() {
                rays += 1;
                let alive = self.bounce(caster, &mut paths[k])?;
                if alive {
                    k += 1;
                } else {
                    let path = paths.swap_remove(k);
                    finished[index.swap_remove(k)] = path.sum;
                }
            }
        }
        let mut moments = Moments { rays, ..Moments::default() };
        for x in finished {
            moments.push_sample(x);
        }
        Ok(moments)
    }

    /// Casts `path`'s bounce ray and moves the path to what it hits; `false` if the path ends (nothing hit, a
    /// back face hit, absorbed by Russian roulette).
    fn bounce<C: RayCaster + ?Sized>(&self, caster: &C, path: &mut Path) -> Result<bool, MonteCarloError> {
        let (s, t) = (path.rng.unit(), path.rng.unit());
        let direction = cosine_direction(path.normal, tangent_frame(path.normal), s, t).normalize();
        let origin = self.lifted(path.point, path.normal);
        let Some(hit) = caster.intersect(&Ray::new(origin, direction.as_vec3(), 0.0, f32::INFINITY)) else {
            return Ok(false);
        };
        let Some(&j) = self.triangle_patch.get(hit.primitive as usize) else {
            return Err(MonteCarloError::CasterMismatch {
                primitive: hit.primitive,
                triangles: self.triangle_patch.len(),
            });
        };
        let j = j as usize;
        let normal = self.patches[j].normal;
        let cos_y = -normal.dot(direction);
        if cos_y.is_nan() || cos_y <= 0.0 {
            // The back of a face: it neither emits nor reflects.
            return Ok(false);
        }
        let distance = f64::from(hit.t);
        let point = origin.as_dvec3() + direction * distance;
        if self.light_density[j] > 0.0 {
            let cosine = path.normal.dot(direction) / std::f64::consts::PI;
            let light = self.light_density[j] * distance * distance / cos_y;
            path.sum += path.throughput * self.emission[j] * (cosine / (light + cosine));
        }
        path.throughput *= self.rho[j];
        // Russian roulette: continue with probability q = min(1, largest channel of the throughput) and divide
        // by it, so the estimate stays unbiased and the throughput stays at most about 1.
        let q = rgb::max_channel(path.throughput).min(1.0);
        if q.is_nan() || q <= 0.0 || path.rng.unit() >= q {
            return Ok(false);
        }
        path.throughput /= q;
        path.point = point;
        path.normal = normal;
        path.patch = j;
        Ok(true)
    }
}
