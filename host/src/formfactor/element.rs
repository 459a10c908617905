//! Form factors between elements made on the fly (the nodes of the hierarchical solver), with exactly the kernel
//! integral and visibility rays of the patch-to-patch estimator: [`ElementRules`] holds the rules, [`Element`]
//! one polygon with its precomputed quadratures.

use super::nearfield::{may_see, Receiver};
use super::options::FormFactorOptions;
use super::quadrature::{gauss_legendre, PolygonSampler, Quadrature};
use super::rows::{unoccluded_pair, visible_fraction, PairScratch, RayBuffers, Sender};
use super::{far_field_order, FormFactorError};
use crate::patch::Patch;
use crate::raycast::RayCaster;
use crate::rng::SplitMix64;

thread_local! {
    /// The kernel integral's buffers, reused by every pair a thread estimates (a pair's estimate does not depend
    /// on what they held before).
    static PAIR_SCRATCH: std::cell::RefCell<PairScratch> = std::cell::RefCell::default();
    /// The visibility rays' buffers, likewise.
    static RAY_BUFFERS: std::cell::RefCell<RayBuffers> = std::cell::RefCell::default();
}

/// One element: a planar convex polygon ([`Patch`]) with the quadrature rules and the stratified sampler the
/// estimator uses on it.
#[derive(Clone, Debug)]
pub struct Element {
    patch: Patch,
    sampler: PolygonSampler,
    quadrature: Quadrature,
    far_quadrature: Quadrature,
    /// The polygon's bounding sphere (centre, radius) and its sliver width ([`Receiver`]'s, made once).
    shape: (glam::DVec3, f64, Option<f64>),
}

impl Element {
    /// The element's polygon.
    #[must_use]
    pub fn patch(&self) -> &Patch {
        &self.patch
    }

    /// The element as a near-field receiver judged by the distance to its polygon ([`Receiver::by_polygon`]).
    fn receiver(&self) -> Receiver<'_> {
        let (center, radius, sliver_width) = self.shape;
        Receiver {
            center,
            radius,
            vertices: &self.patch.vertices,
            normal: self.patch.normal,
            sliver_width,
            polygon_gap: true,
        }
    }

    /// The point of the polygon at `(s, t)` in the open unit square, by an area-preserving map (uniform `(s, t)`
    /// give area-uniform points).
    #[must_use]
    pub fn point(&self, s: f64, t: f64) -> glam::DVec3 {
        self.sampler.point(s, t)
    }
}

/// The estimator's rules ([`FormFactorOptions`]: samples per element, rays per pair, seed, far-field rule) for
/// pairs of [`Element`]s.
#[derive(Clone, Debug)]
pub struct ElementRules {
    rule: Vec<(f64, f64)>,
    far_rule: Vec<(f64, f64)>,
    far_field: bool,
    rays_per_pair: usize,
    seed: u64,
}

impl ElementRules {
    /// The rules of `options`.
    ///
    /// # Errors
    /// [`FormFactorError::InvalidOption`] for zero samples or rays.
    pub fn new(options: &FormFactorOptions) -> Result<ElementRules, FormFactorError> {
        if options.samples_per_patch == 0 {
            return Err(FormFactorError::InvalidOption {
                name: "samples_per_patch",
                problem: "must be at least 1",
            });
        }
        if options.rays_per_pair == 0 {
            return Err(FormFactorError::InvalidOption {
                name: "rays_per_pair",
                problem: "must be at least 1",
            });
        }
        let order = (options.samples_per_patch as f64).sqrt().round().max(1.0) as usize;
        Ok(ElementRules {
            rule: gauss_legendre(order),
            far_rule: gauss_legendre(far_field_order(order)),
            far_field: options.far_field,
            rays_per_pair: options.rays_per_pair,
            seed: options.seed,
        })
    }

    /// Occlusion rays per pair.
    #[must_use]
    pub fn rays_per_pair(&self) -> usize {
        self.rays_per_pair
    }

    /// `patch` as an element (its rules precomputed).
    #[must_use]
    pub fn element(&self, patch: Patch) -> Element {
        let shape = {
            let r = Receiver::by_polygon(&patch);
            (r.center, r.radius, r.sliver_width)
        };
        Element {
            sampler: PolygonSampler::new(&patch.vertices),
            quadrature: Quadrature::new(&patch.vertices, &self.rule),
            far_quadrature: Quadrature::new(&patch.vertices, &self.far_rule),
            shape,
            patch,
        }
    }

    /// `U_ij`, the unoccluded form factor from `i` to `j` (the fraction of the power leaving `i` that would reach
    /// `j` were nothing in between), as the patch-to-patch estimator computes it; 0 if the two cannot face each
    /// other.
    #[must_use]
    pub fn unoccluded(&self, i: &Element, j: &Element) -> f64 {
        if !may_see(&i.patch, &j.patch) {
            return 0.0;
        }
        // Near and far judged by the distance to the polygons: an element is often far smaller than the face
        // polygon (or the coarse piece) it exchanges with.
        let own = i.receiver();
        let receiver = j.receiver();
        let sender = Sender {
            patch: &i.patch,
            quadrature: &i.quadrature,
            far_quadrature: &i.far_quadrature,
            own: &own,
        };
        let mut kernels = 0;
        PAIR_SCRATCH.with_borrow_mut(|scratch| {
            unoccluded_pair(&sender, &j.patch, &receiver, &self.rule, self.far_field, scratch, &mut kernels)
        })
    }

    /// The kernel-weighted visible fraction of the pair from [`Self::rays_per_pair`] rays between stratified
    /// points of `i` and `j`, with random numbers from the stream `(seed, stream)` (so equal streams give equal
    /// fractions on any thread), and the rays cast. NaN when every ray fell where the kernel vanishes.
    pub fn visible_fraction<C: RayCaster + ?Sized>(
        &self,
        caster: &C,
        i: &Element,
        j: &Element,
        stream: (u64, u64),
    ) -> (f64, u64) {
        let mut rng = SplitMix64::for_stream(self.seed, stream.0, stream.1);
        RAY_BUFFERS.with_borrow_mut(|buffers| {
            visible_fraction(
                caster,
                (&i.patch, &i.sampler),
                (&j.patch, &j.sampler),
                &mut rng,
                self.rays_per_pair,
                f64::from(caster.offset()),
                buffers,
            )
        })
    }
}
