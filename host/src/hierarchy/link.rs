//! Links and their refinement: the form-factor estimate of a (receiver, sender) pair of nodes with its spread
//! (how far the point-wise transfer across the receiver may stray from it), the error oracle, and the waves of
//! refinement that split links until every one is within the error bound.

use std::f64::consts::PI;

use rayon::prelude::*;

use super::span::Span;
use super::tree::{Kind, Tree};
use super::HierarchyError;
use crate::formfactor::{point_to_polygon_with, Element, ElementRules};
use crate::raycast::{Ray, RayCaster};
use crate::rgb::max_channel;
use crate::rng::SplitMix64;

/// Salt of the random streams of cluster links (so they never coincide with surface pairs' visibility streams).
const CLUSTER_STREAM: u64 = 0x9e37_79b9_7f4a_7c15;

/// Largest relative standard error of a cluster link's Monte Carlo estimate that is accepted when its ends are
/// near each other (`A_b / (pi d^2) > 1` either way, `d` the gap between the bounding spheres). Near a contact
/// (a block standing on the floor, both in one cluster pair) the point kernel `1 / r^2` is heavy-tailed: one
/// sample pair that lands close dominates the mean, and its relative standard error is then about 1; such an
/// estimate (which can exceed a form factor of 1) says nothing, and accepting it while the sender is still dark
/// (pass 1 judges by emission alone) made the iteration diverge. Farther apart every sample is bounded and any
/// estimate is accepted, however noisy (see [`Estimator::estimate`]'s cluster case): demanding this relative
/// error there opened every pair of furniture whose surfaces mostly face away or are hidden from each other
/// (few of 32 sample pairs see each other) down to its polygons.
pub(super) const MAX_CLUSTER_RELATIVE_ERROR: f64 = 0.25;

/// How far toward its centroid a receiver's vertex is moved to probe the point-wise form factor there (so that a
/// probe never lies on a neighbour's edge, where the kernel is singular in its derivatives).
const PROBE_INSET: f64 = 0.02;

/// One accepted link between two nodes, carrying both directions: `a` gathers `f_ab * B_b` per unit area and `b`
/// gathers `f_ba * B_a`, with `A_a f_ab = A_b f_ba` (reciprocity, so that the exchange conserves power whatever
/// the link's level).
#[derive(Clone, Copy, Debug)]
pub(super) struct Link {
    /// One end.
    pub(super) a: u32,
    /// The other end.
    pub(super) b: u32,
    /// The form factor from `a` to `b`, averaged over `a`.
    pub(super) f_ab: f64,
    /// The form factor from `b` to `a`, averaged over `b`.
    pub(super) f_ba: f64,
    /// Bound on how far the point-wise form factor to `b` across `a` may be from `f_ab`.
    pub(super) spread_ab: f64,
    /// The same for `b` to `a`.
    pub(super) spread_ba: f64,
    /// The visible fraction of a surface-surface link (1 for a link with a cluster, where `f` includes it).
    pub(super) visible: f64,
    /// The unoccluded form factor from `a` to `b` of a surface-surface link (`f_ab` for a link with a cluster).
    pub(super) unoccluded_ab: f64,
    /// The uncertainty of `visible` (see [`visibility_uncertainty`]): its standard error where the rays found it
    /// partial, the resolution of their count where they saw all or nothing, 0 where it is exact (a clear shaft,
    /// or a link with a cluster, whose `f` includes its visibility).
    pub(super) sigma: f64,
}

/// The uncertainty of a visible fraction `v` found by `n` rays: its standard error `sqrt(v (1 - v) / n)` where it
/// is partial, the resolution `1 / n` of the count where the rays saw all or nothing.
pub(super) fn visibility_uncertainty(v: f64, n: f64) -> f64 {
    if v > 0.0 && v < 1.0 {
        (v * (1.0 - v) / n).sqrt()
    } else {
        1.0 / n
    }
}

/// A candidate pair of nodes, and whether nothing can block a ray between them: known for the pairs made by
/// splitting a surface link whose shaft was clear ([`super::shaft`]), since the convex hull of parts of two
/// polygons lies within the hull of the two, so that their shaft is clear too and need not be tested again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Pair {
    /// One end (the receiver, for the pieces' split).
    pub(super) a: u32,
    /// The other end.
    pub(super) b: u32,
    /// Whether the pair's shaft is known to be clear.
    pub(super) clear: bool,
}

impl Pair {
    /// The pair `(a, b)`, its shaft not known to be clear.
    pub(super) fn new(a: u32, b: u32) -> Pair {
        Pair { a, b, clear: false }
    }
}

impl Link {
    /// The pair of the link's ends, clear if it is a surface link whose shaft was clear (its visibility exact:
    /// `visible` 1 with no uncertainty, which the rays never give).
    pub(super) fn pair(&self, tree: &Tree) -> Pair {
        let surfaces = !tree.is_cluster(self.a) && !tree.is_cluster(self.b);
        Pair { a: self.a, b: self.b, clear: surfaces && self.visible == 1.0 && self.sigma == 0.0 }
    }
}

/// The estimate of one candidate pair: a [`Link`] and the rays it cast.
#[derive(Clone, Copy, Debug)]
pub(super) struct Estimate {
    /// The link it would be.
    pub(super) link: Link,
    /// Whether the estimate can be trusted at all (see [`MAX_CLUSTER_RELATIVE_ERROR`]); one that cannot is split
    /// whatever its brightness.
    trusted: bool,
    /// Occlusion rays cast.
    pub(super) rays: u64,
}

/// What the estimates need besides the tree.
pub(super) struct Estimator<'a, C: ?Sized> {
    /// The estimator's rules.
    pub(super) rules: &'a ElementRules,
    /// Occluders.
    pub(super) caster: &'a C,
    /// Point pairs (and rays) of a link with a cluster at one end.
    pub(super) cluster_samples: usize,
    /// Seed of the cluster links' streams.
    pub(super) seed: u64,
    /// Whether surface pairs are shaft-culled ([`super::shaft`]): the caster must then hold no occluders but
    /// (some of) the tree's face polygons.
    pub(super) shafts: bool,
    /// Where refinement reports how far it got on stderr (long passes), if anywhere.
    pub(super) progress: Option<&'a Progress>,
}

/// Refinement's progress lines: at most one every [`Progress::EVERY`] of wall time.
pub(super) struct Progress {
    /// When the solve started.
    started: std::time::Instant,
    /// Milliseconds after `started` of the last line (or of the start).
    last: std::sync::atomic::AtomicU64,
}

impl Progress {
    /// Time between two lines.
    const EVERY: std::time::Duration = std::time::Duration::from_secs(5);

    /// Progress measured from now.
    pub(super) fn new() -> Progress {
        Progress { started: std::time::Instant::now(), last: std::sync::atomic::AtomicU64::new(0) }
    }

    /// Prints where refinement stands if the last line is older than [`Progress::EVERY`].
    fn report(&self, tree: &Tree, links: usize, pending: usize) {
        use std::sync::atomic::Ordering;
        let now = self.started.elapsed();
        let last = std::time::Duration::from_millis(self.last.load(Ordering::Relaxed));
        if now < last + Self::EVERY {
            return;
        }
        self.last.store(now.as_millis() as u64, Ordering::Relaxed);
        let leaves = tree.nodes.iter().filter(|n| n.children.is_empty()).count();
        eprintln!(
            "hierarchy: {links} links, {pending} pairs to estimate, {leaves} leaves after {:.0} s",
            now.as_secs_f64()
        );
    }
}

/// The range of the point kernel from probes of `r` (its centroid and its vertices moved inward) to `s`, or `None`
/// if no probe gave a finite value.
fn kernel_range(r: &Element, s: &Element) -> Option<f64> {
    let (pr, ps) = (r.patch(), s.patch());
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let probes =
        std::iter::once(pr.centroid).chain(pr.vertices.iter().map(|&p| p + PROBE_INSET * (pr.centroid - p)));
    CLIPPED.with_borrow_mut(|clipped| {
        for x in probes {
            let k = point_to_polygon_with(x, pr.normal, &ps.vertices, ps.normal, clipped);
            if k.is_finite() {
                lo = lo.min(k);
                hi = hi.max(k);
            }
        }
    });
    (hi >= lo).then_some(hi - lo)
}

thread_local! {
    /// [`kernel_range`]'s clipped polygon, reused by every pair a thread estimates.
    static CLIPPED: std::cell::RefCell<Vec<glam::DVec3>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl<'a, C: RayCaster + ?Sized> Estimator<'a, C> {
    /// The estimator the unit tests use: `rules`, occluders `caster` (no others than the tree's polygons: shaft
    /// culling is on), 32 point pairs per cluster link, seed 1, no progress output.
    #[cfg(test)]
    pub(super) fn for_tests(rules: &'a ElementRules, caster: &'a C) -> Estimator<'a, C> {
        Estimator { rules, caster, cluster_samples: 32, seed: 1, shafts: true, progress: None }
    }

    /// The estimate of the pair `(a, b)` (distinct, disjoint nodes).
    #[cfg(test)]
    pub(super) fn estimate(&self, tree: &Tree, pair: Pair) -> Estimate {
        self.estimate_unless(tree, pair, &|_| false)
    }

    /// [`Self::estimate`], except that a surface pair for which `split` holds with its spreads' visibility parts
    /// alone (before the kernel ranges over probes of both ends are added) is returned with those: the oracle's
    /// error grows with the spreads, so such a pair is split whatever the ranges, and refinement needs no more of
    /// it than that.
    pub(super) fn estimate_unless(
        &self,
        tree: &Tree,
        Pair { a, b, clear }: Pair,
        split: &(dyn Fn(&Link) -> bool + Sync),
    ) -> Estimate {
        let zero = Estimate {
            link: Link {
                a,
                b,
                f_ab: 0.0,
                f_ba: 0.0,
                spread_ab: 0.0,
                spread_ba: 0.0,
                visible: 1.0,
                unoccluded_ab: 0.0,
                sigma: 0.0,
            },
            trusted: true,
            rays: 0,
        };
        if tree.behind(a, b) || tree.behind(b, a) {
            return zero;
        }
        let (na, nb) = (&tree.nodes[a as usize], &tree.nodes[b as usize]);
        match (&na.kind, &nb.kind) {
            (Kind::Surface { element: ea, .. }, Kind::Surface { element: eb, .. }) => {
                self.surface_pair(tree, (a, ea), (b, eb), clear, split).unwrap_or(zero)
            }
            _ => self.cluster_pair(tree, a, b),
        }
    }

    /// Two surfaces: the kernel's unoccluded form factor times the visible fraction (as the patch-to-patch
    /// estimator computes them, from occlusion rays; exactly 1 without a ray where no face polygon reaches into
    /// the pair's hull, [`super::shaft`]); the spread is the point-wise form factor's range over probes of the
    /// receiver times the visible fraction, plus, where visibility is partial, the whole unoccluded factor (a
    /// shadow edge can cross the receiver) and the fraction's standard error; where it is not, its uncertainty
    /// ([`visibility_uncertainty`]; 0 for a clear shaft) times the unoccluded factor. `None` if the two cannot
    /// exchange light. `clear` says the shaft is known to be clear (not tested again); `split` as in
    /// [`Self::estimate_unless`].
    pub(super) fn surface_pair(
        &self,
        tree: &Tree,
        (a, ea): (u32, &Element),
        (b, eb): (u32, &Element),
        clear: bool,
        split: &(dyn Fn(&Link) -> bool + Sync),
    ) -> Option<Estimate> {
        let (mut estimate, u_ba) = self.factor(tree, (a, ea), (b, eb), clear)?;
        let link = &mut estimate.link;
        let (v, sigma) = (link.visible, link.sigma);
        let visibility = if v > 0.0 && v < 1.0 { 1.0 + sigma } else { sigma };
        link.spread_ab = link.unoccluded_ab * visibility;
        link.spread_ba = u_ba * visibility;
        if split(link) {
            return Some(estimate);
        }
        link.spread_ab += v * kernel_range(ea, eb).unwrap_or(link.unoccluded_ab);
        link.spread_ba += v * kernel_range(eb, ea).unwrap_or(u_ba);
        Some(estimate)
    }

    /// [`Self::surface_pair`] without the spreads (left 0, which saves the probes' kernel evaluations): the form
    /// factors, the visible fraction and its uncertainty, for a caller that needs no more; and the unoccluded form
    /// factor from `b` to `a`. `clear` says the shaft is known to be clear (not tested again).
    pub(super) fn factor(
        &self,
        tree: &Tree,
        (a, ea): (u32, &Element),
        (b, eb): (u32, &Element),
        clear: bool,
    ) -> Option<(Estimate, f64)> {
        // Integrated over the smaller of the two (the kernel is exact over the other), the other direction by
        // reciprocity: the quadrature then never has to resolve a small neighbour's peak on a large element.
        let (aa, ab) = (ea.patch().area, eb.patch().area);
        let (u_ab, u_ba) = if aa <= ab {
            let u = self.rules.unoccluded(ea, eb);
            (u, u * aa / ab)
        } else {
            let u = self.rules.unoccluded(eb, ea);
            (u * ab / aa, u)
        };
        if !(u_ab > 0.0 && u_ab.is_finite() && u_ba.is_finite()) {
            return None;
        }
        let (v, sigma, rays) = if self.shafts && (clear || super::shaft::clear(tree, a, b)) {
            (1.0, 0.0, 0)
        } else {
            // The stream of the lower key first, so the estimate does not depend on the pair's order (nor, keyed
            // by the nodes' keys, on when refinement made them).
            let (ka, kb) = (tree.nodes[a as usize].key, tree.nodes[b as usize].key);
            let (v, rays) = if ka < kb {
                self.rules.visible_fraction(self.caster, ea, eb, (ka, kb))
            } else {
                self.rules.visible_fraction(self.caster, eb, ea, (kb, ka))
            };
            let v = if v.is_nan() { 1.0 } else { v };
            (v, visibility_uncertainty(v, self.rules.rays_per_pair() as f64), rays)
        };
        let link = Link {
            a,
            b,
            f_ab: u_ab * v,
            f_ba: u_ba * v,
            spread_ab: 0.0,
            spread_ba: 0.0,
            visible: v,
            unoccluded_ab: u_ab,
            sigma,
        };
        Some((Estimate { link, trusted: true, rays }, u_ba))
    }

    /// A cluster at one end (or both): Monte Carlo over area-uniform point pairs with a shadow ray each,
    /// `F_ab = A_b * mean(cos+ cos+ V / (pi r^2))` (and `F_ba` with `A_a`). The spread is the bound on any point's
    /// form factor to the other end (`A_b / (pi d^2)` with `d` the gap between the bounding spheres, at most 1; 1
    /// if they overlap), which bounds the error of giving every point of a cluster the same value (Smits, Arvo,
    /// Greenberg 1994), plus two standard errors of the mean. Where that bound is at most 1 both ways, each
    /// sample `A_b k` lies in `[0, A_b / (pi d^2)]`, so the estimate is trusted whatever its relative error;
    /// nearer, only with a relative standard error of at most [`MAX_CLUSTER_RELATIVE_ERROR`] and a form factor
    /// of at most 1 both ways.
    fn cluster_pair(&self, tree: &Tree, a: u32, b: u32) -> Estimate {
        let (na, nb) = (&tree.nodes[a as usize], &tree.nodes[b as usize]);
        let (lo, hi) = if na.key < nb.key { (a, b) } else { (b, a) };
        let (klo, khi) = (tree.nodes[lo as usize].key, tree.nodes[hi as usize].key);
        let mut rng = SplitMix64::for_stream(self.seed ^ CLUSTER_STREAM, klo, khi);
        let offset = self.caster.offset();
        let n = self.cluster_samples;
        let mut values = Vec::with_capacity(n);
        let mut rays = Vec::with_capacity(n);
        let mut slots = Vec::with_capacity(n);
        for _ in 0..n {
            let (x, nx) = tree.sample(lo, &mut rng);
            let (y, ny) = tree.sample(hi, &mut rng);
            let d = y - x;
            let r2 = d.length_squared();
            let k = (nx.dot(d) * -ny.dot(d)).max(0.0) / (r2 * r2 * PI);
            if k > 0.0 && k.is_finite() {
                slots.push(values.len());
                rays.push(Ray::segment(x.as_vec3(), y.as_vec3(), offset));
            }
            values.push(if k.is_finite() { k } else { 0.0 });
        }
        let mut occluded = vec![false; rays.len()];
        self.caster.occluded_many(&rays, &mut occluded);
        for (&slot, &blocked) in slots.iter().zip(&occluded) {
            if blocked {
                values[slot] = 0.0;
            }
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n.max(2) - 1) as f64;
        let se = (var / n as f64).sqrt();
        let (g_ab, g_ba) = geometric_bounds(tree, a, b);
        // Far enough apart that no sample can claim more than the whole hemisphere (`A k <= g <= 1` both ways):
        // the estimate, however few of its pairs see each other, lies in `[0, g]` like the true form factor of
        // every point, which is the oracle's geometric charge; only nearer pairs need a small relative error.
        let bounded = g_ab.max(g_ba) <= 1.0;
        let trusted = bounded
            || (se <= MAX_CLUSTER_RELATIVE_ERROR * mean && nb.area * mean <= 1.0 && na.area * mean <= 1.0);
        let link = Link {
            a,
            b,
            f_ab: nb.area * mean,
            f_ba: na.area * mean,
            spread_ab: g_ab.min(1.0) + 2.0 * nb.area * se,
            spread_ba: g_ba.min(1.0) + 2.0 * na.area * se,
            visible: 1.0,
            unoccluded_ab: nb.area * mean,
            sigma: 0.0,
        };
        Estimate { link, trusted: trusted || mean == 0.0, rays: rays.len() as u64 }
    }
}

/// The bound on any point's form factor to the other end of a pair with a cluster, before the cap at 1, both
/// ways: `(A_b / (pi d^2), A_a / (pi d^2))` with `d` the gap between the nodes' bounding spheres (infinite if
/// they touch or overlap).
fn geometric_bounds(tree: &Tree, a: u32, b: u32) -> (f64, f64) {
    let (na, nb) = (&tree.nodes[a as usize], &tree.nodes[b as usize]);
    let d = na.center.distance(nb.center) - na.radius - nb.radius;
    let bound = |area: f64| if d > 0.0 { area / (PI * d * d) } else { f64::INFINITY };
    (bound(nb.area), bound(na.area))
}

/// The error oracle: the power a link may misplace at either end, `A_r * max_c(rho_r,c * Bmax_s,c) * spread_rs`
/// (brightness-weighted refinement, Hanrahan, Salzman, Aupperle 1991, with the spread in place of `F`), the
/// larger of the two directions.
///
/// Between two surfaces, `sender_weight` (`w`, [`super::HierarchyOptions::sender_weight`]) adds the sender's
/// unevenness: the link sends its average radiosity, where a receiver point gathers each part of the sender by
/// its own kernel, so it may be off by up to `F_rs * (Bmax_s - Bmin_s)` per unit area (the leaves' range below
/// the sender); the charge adds `w` times that. The brightness term alone leaves a link coarse wherever its
/// form factor varies little over the receiver, however uneven the sender (a floor lit brightly in the middle
/// and dimly at its edges, sending its average to the block side beside a dim edge).
///
/// A link with a cluster at either end bounds its geometric part by the sender's power instead: no point of the
/// receiver gets more irradiance from the sender than `Phi_s / (pi d^2)` (`d` the gap between the bounding
/// spheres; Smits, Arvo, Greenberg 1994), and none gets less than 0, so neither the receiver's spread of point
/// values nor the sender's uneven radiosity (a cluster whose few bright surfaces face another way than its
/// average) can misplace more per unit area: the charge is `min(A_s * mean_s / (pi d^2), Bmax_s)` per unit
/// area, where the spread's `min(A_s / (pi d^2), 1)` times `Bmax_s` would charge every surface of a cluster as if
/// it were its brightest (a ceiling cluster holding a few panels). The Monte Carlo term (two standard errors) is
/// charged at `Bmax_s` as before.
pub(super) fn link_error(tree: &Tree, spans: &[Span], link: &Link, sender_weight: f64) -> f64 {
    let clustered = tree.is_cluster(link.a) || tree.is_cluster(link.b);
    let geometric = clustered.then(|| geometric_bounds(tree, link.a, link.b));
    let one = |r: u32, s: u32, f: f64, spread: f64, bound: Option<f64>| {
        let nr = &tree.nodes[r as usize];
        let span = &spans[s as usize];
        let brightness = match bound {
            Some(g) => {
                let noise = (spread - g.min(1.0)).max(0.0);
                (span.mean * g).min(span.hi) + span.hi * noise
            }
            None => span.hi * spread + (span.hi - span.lo) * (sender_weight * f),
        };
        nr.area * max_channel(nr.rho_max * brightness)
    };
    one(link.a, link.b, link.f_ab, link.spread_ab, geometric.map(|g| g.0)).max(one(
        link.b,
        link.a,
        link.f_ba,
        link.spread_ba,
        geometric.map(|g| g.1),
    ))
}

/// Counters of refinement.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RefineCounts {
    /// Pairs estimated.
    pub(super) estimated: u64,
    /// Occlusion rays cast.
    pub(super) rays: u64,
    /// Links kept although above the bound, both ends at the resolution or node limit.
    pub(super) at_limit: u64,
    /// Links split.
    pub(super) split: u64,
    /// Of those, the cluster links split because their estimate could not be trusted (see
    /// [`MAX_CLUSTER_RELATIVE_ERROR`]), whatever their brightness.
    pub(super) untrusted: u64,
}

impl RefineCounts {
    /// Adds `other`'s counts (a piece's) to these.
    pub(super) fn add(&mut self, other: &RefineCounts) {
        self.estimated += other.estimated;
        self.rays += other.rays;
        self.at_limit += other.at_limit;
        self.split += other.split;
        self.untrusted += other.untrusted;
    }
}

/// Limits of refinement.
#[derive(Clone, Copy)]
pub(super) struct Limits {
    /// Error bound per link (W).
    pub(super) threshold: f64,
    /// Surfaces below 4 times this area are not split.
    pub(super) min_area: f64,
    /// Most nodes.
    pub(super) max_nodes: usize,
    /// Most links, accepted and pending together: refinement stops with [`HierarchyError::TooManyLinks`]
    /// before it would hold more.
    pub(super) max_links: usize,
    /// Receiver-subtree pieces a refinement runs in (`pieces`; 1: one piece, in place). Any count gives the same
    /// links and nodes, bit for bit.
    pub(super) pieces: usize,
    /// Weight of the sender's unevenness in [`link_error`] ([`super::HierarchyOptions::sender_weight`]).
    pub(super) sender_weight: f64,
}

/// How many children splitting surface `n` makes (the mesher's split: 4 for a triangle or a quadrilateral, one
/// per vertex of a larger polygon).
fn split_count(tree: &Tree, n: u32) -> usize {
    let vertices = tree.nodes[n as usize].element().map_or(4, |e| e.patch().vertices.len());
    if vertices == 3 {
        4
    } else {
        vertices.max(4)
    }
}

/// Whether `n` may be split: a cluster always, a surface while its children would be at least `min_area`. (The
/// node limit is an error, [`HierarchyError::TooManyNodes`], not a reason to keep a link: what is split must not
/// depend on the order of the splits, so that pieces merge to the one-piece answer.)
fn splittable(tree: &Tree, limits: &Limits, n: u32) -> bool {
    let node = &tree.nodes[n as usize];
    if tree.is_cluster(n) || !node.children.is_empty() {
        return true;
    }
    node.area / split_count(tree, n) as f64 >= limits.min_area
}

/// The pairs a self-link of `n` stands for: every unordered pair of distinct children, and the self-links of the
/// children that are clusters (a planar surface does not see itself).
pub(super) fn expand_self(tree: &Tree, n: u32, candidates: &mut Vec<Pair>) {
    let mut stack = vec![n];
    while let Some(c) = stack.pop() {
        if !tree.is_cluster(c) {
            continue;
        }
        let children = &tree.nodes[c as usize].children;
        for (k, &a) in children.iter().enumerate() {
            for &b in &children[k + 1..] {
                candidates.push(Pair::new(a, b));
            }
            stack.push(a);
        }
    }
}

/// Estimates `candidates` in waves (in parallel within a wave), accepting each that is within the bound and
/// replacing each that is not by the pairs of the children of its larger splittable end; appends the accepted
/// links to `links`. A pair whose receiver end (`a`) `here` refuses is set aside in `elsewhere` instead (the
/// pieces' split). `held` links are held outside `links` (other pieces'), for the link limit.
///
/// # Errors
/// As [`refine`].
#[allow(clippy::too_many_arguments)]
pub(super) fn waves<C: RayCaster + ?Sized>(
    tree: &mut Tree,
    estimator: &Estimator<'_, C>,
    spans: &mut Vec<Span>,
    limits: &Limits,
    mut candidates: Vec<Pair>,
    links: &mut Vec<Link>,
    counts: &mut RefineCounts,
    held: usize,
    here: impl Fn(&Tree, u32) -> bool,
    elsewhere: &mut Vec<Pair>,
) -> Result<(), HierarchyError> {
    loop {
        candidates.retain(|&pair| {
            here(tree, pair.a) || {
                elsewhere.push(pair);
                false
            }
        });
        if candidates.is_empty() {
            break;
        }
        if held + links.len() + candidates.len() > limits.max_links {
            return Err(too_many_links(tree, limits, held + links.len(), candidates.len(), counts));
        }
        if let Some(p) = estimator.progress {
            p.report(tree, links.len(), candidates.len());
        }
        let estimates: Vec<Estimate> = {
            let tree = &*tree;
            let spans = &*spans;
            let above = |l: &Link| link_error(tree, spans, l, limits.sender_weight) > limits.threshold;
            candidates.par_iter().map(|&pair| estimator.estimate_unless(tree, pair, &above)).collect()
        };
        let mut next = Vec::new();
        for est in &estimates {
            counts.estimated += 1;
            counts.rays += est.rays;
            let link = est.link;
            if link.f_ab == 0.0 && link.spread_ab == 0.0 && link.spread_ba == 0.0 {
                continue;
            }
            if est.trusted && link_error(tree, spans, &link, limits.sender_weight) <= limits.threshold {
                // A pair whose rays all missed may still exchange light somewhere: kept (it carries no transfer)
                // so that the budgets can refine it.
                links.push(link);
                continue;
            }
            let split = if est.trusted {
                split_link(tree, estimator.rules, spans, limits, link.pair(tree), &mut next)?
            } else {
                split_untrusted(tree, estimator.rules, spans, limits, link.pair(tree), &mut next)?
            };
            if split {
                counts.split += 1;
                counts.untrusted += u64::from(!est.trusted);
            } else {
                counts.at_limit += 1;
                links.push(link);
            }
        }
        candidates = next;
    }
    Ok(())
}

/// The error for refinement that would exceed `limits.max_links` (the pass is filled in by the driver).
pub(super) fn too_many_links(
    tree: &Tree,
    limits: &Limits,
    links: usize,
    pending: usize,
    counts: &RefineCounts,
) -> HierarchyError {
    HierarchyError::TooManyLinks {
        limit: limits.max_links,
        links,
        pending,
        leaves: tree.nodes.iter().filter(|n| n.children.is_empty()).count(),
        split: counts.split,
        untrusted: counts.untrusted,
        pass: 0,
    }
}

/// Whether either end of `link` can be split.
pub(super) fn can_split(tree: &Tree, limits: &Limits, link: &Link) -> bool {
    splittable(tree, limits, link.a) || splittable(tree, limits, link.b)
}

/// Replaces the pair `(r, s)` by the pairs of the children of its larger splittable end (by area; `r` on a
/// tie); returns false if neither end can be split.
///
/// # Errors
/// [`HierarchyError::Mesh`] if a surface cannot be split.
pub(super) fn split_link(
    tree: &mut Tree,
    rules: &ElementRules,
    spans: &mut Vec<Span>,
    limits: &Limits,
    pair: Pair,
    next: &mut Vec<Pair>,
) -> Result<bool, HierarchyError> {
    let (r, s) = (pair.a, pair.b);
    let first = if tree.nodes[r as usize].area >= tree.nodes[s as usize].area { r } else { s };
    split_either(tree, rules, spans, limits, pair, first, next)
}

/// Splits `pair` at `first` (one of its ends), or at the other end if `first` cannot be split; returns false if
/// neither can.
///
/// # Errors
/// [`HierarchyError::Mesh`] if a surface cannot be split.
pub(super) fn split_either(
    tree: &mut Tree,
    rules: &ElementRules,
    spans: &mut Vec<Span>,
    limits: &Limits,
    pair: Pair,
    first: u32,
    next: &mut Vec<Pair>,
) -> Result<bool, HierarchyError> {
    let second = if first == pair.a { pair.b } else { pair.a };
    Ok(split_end(tree, rules, spans, limits, pair, first, next)?
        || split_end(tree, rules, spans, limits, pair, second, next)?)
}

/// Replaces a pair whose cluster estimate cannot be trusted by the pairs of the children of its cluster end (the
/// larger if both are clusters), or of its other end if the cluster cannot be split: opening the cluster is what
/// removes the doubt (its surfaces' pairs have the kernel integrated exactly), while splitting a surface facing
/// an unopened cluster only repeats the doubtful estimate on every piece.
///
/// # Errors
/// [`HierarchyError::Mesh`] if a surface cannot be split.
fn split_untrusted(
    tree: &mut Tree,
    rules: &ElementRules,
    spans: &mut Vec<Span>,
    limits: &Limits,
    pair: Pair,
    next: &mut Vec<Pair>,
) -> Result<bool, HierarchyError> {
    let (r, s) = (pair.a, pair.b);
    let (cr, cs) = (tree.is_cluster(r), tree.is_cluster(s));
    let first = match (cr, cs) {
        (true, false) => r,
        (false, true) => s,
        _ if tree.nodes[r as usize].area >= tree.nodes[s as usize].area => r,
        _ => s,
    };
    split_either(tree, rules, spans, limits, pair, first, next)
}

/// Replaces `pair` by the pairs of the children of its end `end` (`pair.a` or `pair.b`) with the other end, if
/// `end` can be split; returns whether it could. New surface children take their parent's brightness range
/// until a solve gives them their own; the new pairs' shafts are clear if the pair's was.
///
/// # Errors
/// [`HierarchyError::Mesh`] if a surface cannot be split.
pub(super) fn split_end(
    tree: &mut Tree,
    rules: &ElementRules,
    spans: &mut Vec<Span>,
    limits: &Limits,
    pair: Pair,
    end: u32,
    next: &mut Vec<Pair>,
) -> Result<bool, HierarchyError> {
    let Pair { a, b, clear } = pair;
    if !splittable(tree, limits, end) {
        return Ok(false);
    }
    if tree.nodes[end as usize].children.is_empty()
        && tree.nodes.len() + split_count(tree, end) > limits.max_nodes
    {
        return Err(HierarchyError::TooManyNodes {
            limit: limits.max_nodes,
            nodes: tree.nodes.len(),
            pass: 0,
        });
    }
    tree.split(rules, end).map_err(HierarchyError::Mesh)?;
    while spans.len() < tree.nodes.len() {
        let parent = tree.nodes[spans.len()].parent;
        spans.push(spans[parent as usize]);
    }
    for &c in &tree.nodes[end as usize].children {
        next.push(if end == a { Pair { a: c, b, clear } } else { Pair { a, b: c, clear } });
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::super::testing::{cornell_polygons, within};
    use super::*;
    use crate::formfactor::point_to_polygon;
    use crate::rgb::Rgb;

    /// The oracle's charge for a cluster link with the light in its cluster: never more than the brightest-
    /// radiosity charge it replaces, less where the cluster's emitting part is a small share of its area, and
    /// never less than the largest power a receiver point can gather from the cluster's emitters unoccluded
    /// (the exact point-to-polygon form factor at the receiver's centroid and vertices), which the link's
    /// single value misplaces at most.
    #[test]
    fn a_cluster_link_is_charged_at_the_senders_power_and_still_bounds_its_error() {
        let (roots, lighting, rules) = cornell_polygons();
        let tree = Tree::new(&rules, &roots, &lighting.rho, &lighting.default_emission());
        let spans = super::super::solve::emission_bound(&tree);
        let n = tree.nodes.len() as u32;
        let within = |k: u32, c: u32| within(&tree, k, c);
        let emitters: Vec<u32> = (0..n)
            .filter(|&k| match &tree.nodes[k as usize].kind {
                Kind::Surface { emission, .. } => max_channel(*emission) > 0.0,
                Kind::Cluster { .. } => false,
            })
            .collect();
        let (mut pairs, mut cheaper) = (0, 0);
        for c in (0..n).filter(|&c| tree.is_cluster(c) && emitters.iter().any(|&e| within(e, c))) {
            for r in (0..n).filter(|&r| !tree.is_cluster(r) && !within(r, c)) {
                let (g, _) = geometric_bounds(&tree, r, c);
                if g >= 1.0 {
                    continue;
                }
                let link = Link {
                    a: r,
                    b: c,
                    f_ab: 0.0,
                    f_ba: 0.0,
                    spread_ab: g,
                    spread_ba: 0.0,
                    visible: 1.0,
                    unoccluded_ab: 0.0,
                    sigma: 0.0,
                };
                let charge = link_error(&tree, &spans, &link, 0.0);
                let nr = &tree.nodes[r as usize];
                let brightest = nr.area * max_channel(nr.rho_max * spans[c as usize].hi) * g;
                assert!(charge <= brightest * (1.0 + 1e-12), "({r}, {c}): {charge} > {brightest}");
                // The largest unoccluded irradiance of a receiver point from the cluster's emitters.
                let pr = nr.element().unwrap().patch();
                let probes = std::iter::once(pr.centroid).chain(pr.vertices.iter().copied());
                let mut most = Rgb::ZERO;
                for x in probes {
                    let mut gathered = Rgb::ZERO;
                    for &e in emitters.iter().filter(|&&e| within(e, c)) {
                        let ne = &tree.nodes[e as usize];
                        let Kind::Surface { element, emission, .. } = &ne.kind else { unreachable!() };
                        let pe = element.patch();
                        let k = point_to_polygon(x, pr.normal, &pe.vertices, pe.normal);
                        if k.is_finite() {
                            gathered += k.max(0.0) * *emission;
                        }
                    }
                    most = crate::rgb::channel_max(most, gathered);
                }
                let exact = nr.area * max_channel(nr.rho_max * most);
                assert!(exact <= charge * (1.0 + 1e-9), "({r}, {c}): gathers {exact}, charged {charge}");
                pairs += 1;
                cheaper += usize::from(charge < 0.5 * brightest);
            }
        }
        assert!(pairs > 0 && cheaper > 0, "{pairs} pairs, {cheaper} charged at most half");
    }

    /// The sender term of the oracle: a surface link whose form factor varies nowhere over its receiver (spread
    /// 0) is charged nothing at sender weight 0, and at weight `w` exactly `w * F * A_r * max_c(rho_r,c *
    /// (Bmax_s,c - Bmin_s,c))`: linear in `w`, zero where the sender is even, and never applied to a cluster
    /// link (charged by its geometric bound whatever the weight).
    #[test]
    fn the_senders_unevenness_is_charged_by_its_weight_on_surface_links_only() {
        let (roots, lighting, rules) = cornell_polygons();
        let tree = Tree::new(&rules, &roots, &lighting.rho, &lighting.default_emission());
        let mut spans = super::super::solve::emission_bound(&tree);
        let n = tree.nodes.len() as u32;
        let surfaces: Vec<u32> = (0..n).filter(|&k| !tree.is_cluster(k)).collect();
        let (r, s) = (surfaces[0], surfaces[1]);
        let f = 0.125;
        let link = |a: u32, b: u32| Link {
            a,
            b,
            f_ab: f,
            f_ba: 0.0,
            spread_ab: 0.0,
            spread_ba: 0.0,
            visible: 1.0,
            unoccluded_ab: f,
            sigma: 0.0,
        };
        // An even sender: no charge at any weight.
        spans[s as usize].hi = Rgb::new(2.0, 1.0, 0.5);
        spans[s as usize].lo = spans[s as usize].hi;
        for w in [0.0, 1.0, 16.0] {
            assert_eq!(link_error(&tree, &spans, &link(r, s), w), 0.0);
        }
        // An uneven one: the range times F times the weight.
        spans[s as usize].lo = Rgb::new(0.5, 1.0, 0.25);
        let nr = &tree.nodes[r as usize];
        let one = nr.area * max_channel(nr.rho_max * Rgb::new(1.5, 0.0, 0.25)) * f;
        assert!(one > 0.0);
        assert_eq!(link_error(&tree, &spans, &link(r, s), 0.0), 0.0);
        for w in [1.0, 16.0] {
            let charge = link_error(&tree, &spans, &link(r, s), w);
            assert!((charge - w * one).abs() <= 1e-12 * w * one, "weight {w}: {charge} vs {}", w * one);
        }
        // A cluster sender is charged by its geometric bound, the same at every weight.
        let c = (0..n).find(|&k| tree.is_cluster(k) && !within(&tree, r, k)).unwrap();
        spans[c as usize].lo = Rgb::ZERO;
        let clustered = link(r, c);
        assert_eq!(link_error(&tree, &spans, &clustered, 0.0), link_error(&tree, &spans, &clustered, 16.0));
    }

    /// Every Cornell box pair with a cluster end whose ends are far enough apart (`A / (pi d^2) <= 1` both ways)
    /// is trusted and estimated within `[0, A / (pi d^2)]` both ways, the range the oracle's geometric charge
    /// covers, including pairs whose relative standard error is above [`MAX_CLUSTER_RELATIVE_ERROR`] (mostly
    /// hidden or facing away), which the relative rule alone would reject.
    #[test]
    fn a_cluster_pair_far_apart_is_trusted_within_its_geometric_bound() {
        let (roots, lighting, rules) = cornell_polygons();
        let tree = Tree::new(&rules, &roots, &lighting.rho, &lighting.default_emission());
        let caster = crate::formfactor::occluder_scene(&roots, true).unwrap();
        let estimator = Estimator::for_tests(&rules, &caster);
        let n = tree.nodes.len() as u32;
        let (mut far, mut noisy) = (0, 0);
        for a in (0..n).filter(|&a| tree.is_cluster(a)) {
            for b in (0..n).filter(|&b| !within(&tree, b, a) && !within(&tree, a, b)) {
                let (g_ab, g_ba) = geometric_bounds(&tree, a, b);
                if g_ab.max(g_ba) > 1.0 || tree.behind(a, b) || tree.behind(b, a) {
                    continue;
                }
                let est = estimator.estimate(&tree, Pair::new(a, b));
                let l = est.link;
                assert!(est.trusted, "({a}, {b})");
                assert!((0.0..=g_ab).contains(&l.f_ab), "({a}, {b}): f_ab {} above {g_ab}", l.f_ab);
                assert!((0.0..=g_ba).contains(&l.f_ba), "({a}, {b}): f_ba {} above {g_ba}", l.f_ba);
                far += 1;
                // Its standard error, from the spread: two of them above the geometric part.
                let se = (l.spread_ab - g_ab) / (2.0 * tree.nodes[b as usize].area);
                noisy += usize::from(
                    l.f_ab > 0.0 && se * tree.nodes[b as usize].area > MAX_CLUSTER_RELATIVE_ERROR * l.f_ab,
                );
            }
        }
        assert!(far > 0 && noisy > 0, "{far} pairs far apart, {noisy} of them noisy");
    }

    /// A pair of a cluster and a larger surface: with a trusted estimate the larger end (the surface) is split,
    /// with an untrusted one the cluster is opened, whatever the areas.
    #[test]
    fn an_untrusted_pair_opens_its_cluster() {
        let (roots, lighting, rules) = cornell_polygons();
        let tree = Tree::new(&rules, &roots, &lighting.rho, &lighting.default_emission());
        let limits = Limits {
            threshold: 0.0,
            min_area: 0.0,
            max_nodes: 100_000,
            max_links: usize::MAX,
            pieces: 1,
            sender_weight: 0.0,
        };
        // The largest surface, and a cluster smaller than it that does not hold it.
        let n = tree.nodes.len() as u32;
        let surface = (0..n)
            .filter(|&k| !tree.is_cluster(k))
            .max_by(|&x, &y| tree.nodes[x as usize].area.total_cmp(&tree.nodes[y as usize].area))
            .unwrap();
        let holds = |c: u32| within(&tree, surface, c);
        let cluster = (0..n)
            .find(|&k| {
                tree.is_cluster(k)
                    && !holds(k)
                    && tree.nodes[k as usize].area < tree.nodes[surface as usize].area
            })
            .unwrap();
        for untrusted in [false, true] {
            // A fresh tree each time (built deterministically: the same node numbers).
            let mut t = Tree::new(&rules, &roots, &lighting.rho, &lighting.default_emission());
            let (mut spans, mut next) = (vec![Span::ZERO; t.nodes.len()], Vec::new());
            let split = if untrusted {
                split_untrusted(&mut t, &rules, &mut spans, &limits, Pair::new(surface, cluster), &mut next)
                    .unwrap()
            } else {
                split_link(&mut t, &rules, &mut spans, &limits, Pair::new(surface, cluster), &mut next)
                    .unwrap()
            };
            assert!(split && !next.is_empty());
            let opened = if untrusted { cluster } else { surface };
            let children = &t.nodes[opened as usize].children;
            for &Pair { a: r, b: s, .. } in &next {
                let (child, other) = if untrusted { (s, r) } else { (r, s) };
                assert!(children.contains(&child), "untrusted {untrusted}: pair ({r}, {s})");
                assert_eq!(other, if untrusted { surface } else { cluster });
            }
        }
    }
}
