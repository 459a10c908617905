//! Hierarchical radiosity with clustering: links between nodes of an element tree where the light needs them,
//! instead of a form factor for every pair of patches.
//!
//! # Method
//! - **Tree** (`tree`). Every face polygon of the scene is the root of a subdivision tree (the mesher's split:
//!   edge midpoints of a triangle, a 2 x 2 grid of a quadrilateral; areas and centroids exact), made on demand.
//!   Above the polygons, clusters form a bounding-volume hierarchy (median split along the longest axis), so that
//!   distant groups of surfaces exchange light through one link (Smits, Arvo, Greenberg, "A clustering algorithm
//!   for radiosity in complex environments", SIGGRAPH 1994).
//! - **Links** (`link`). A link (receiver, sender) carries the receiver-based form factor `F` (receiver gathers
//!   `F * B_sender` per unit area). Between two surfaces, `F` is the patch estimator's own: the unoccluded kernel
//!   integral times the visible fraction from occlusion rays (`formfactor::ElementRules`), or exactly 1 without a
//!   ray where no face polygon reaches into the convex hull of the two (`shaft`: shaft culling, Haines and
//!   Wallace 1991, through the cluster tree's boxes; [`HierarchyOptions::shaft_culling`]). With a cluster at
//!   either end, `F` is a Monte Carlo estimate over area-uniform point pairs with shadow rays, and the cluster
//!   receives isotropically: every surface in it gets the same irradiance.
//! - **Oracle** (`link`, `budget`). Each link has a spread: a bound on how far the form factor of a point of the
//!   receiver may be from `F` (the range of the point kernel over probe points, the partial-visibility and
//!   ray-count terms for surfaces; `A_s / (pi d^2)` plus two standard errors for clusters, Smits et al.'s
//!   bound, whose geometric part the oracle charges at the sender's power, `Phi_s / (pi d^2)`, not at its
//!   brightest radiosity over its whole area).
//!   Refinement runs in two stages:
//!   1. **Direct light** (pass 1): from the top cluster's self-link, with the brightness of emission alone, a link
//!      whose power error `A_r * max_c(rho_r * Bmax_s) * spread` exceeds `epsilon * LINK_SHARE` times the
//!      brightest face polygon's emitted power is split at its larger end (brightness-weighted refinement,
//!      Hanrahan, Salzman, Aupperle, "A rapid hierarchical radiosity algorithm", SIGGRAPH 1991, with the spread
//!      for `F`). This makes the elements: fine where direct light and its shadows change fast. With
//!      [`HierarchyOptions::sender_weight`] (the command line's f64 answers) a surface link's error also counts
//!      its sender's unevenness, `w * F * (Bmax_s - Bmin_s)` per unit area (the average it sends against what a
//!      receiver point sees; `link::link_error`), in every brightness pass.
//!   2. **Budgets** (each later pass, after a solve): every leaf is charged with what the links on its chain (its
//!      own and its ancestors') may get wrong there, receiver-side (an average pushed down) and sender-side (an
//!      average `B` sent where the sender's bright parts see more); chains above `epsilon` times the leaf's
//!      reflected radiosity are refined at their largest charges (`budget` has the terms and why both matter).
//!      Or, with [`Refinement::Brightness`] (device tables), pass 1's rule again with the solved radiosity
//!      (`link::refine_brightness`), plus the links on the chain of every leaf that gathers more than 1 in all,
//!      where an ancestor's average overstates the leaf's own point form factor most (`excess`), and the
//!      surface links held at an ancestor that a leaf below sees much less of (`shadow`; links whose shaft is
//!      clear are not checked, nothing can shadow a leaf below them): the leaf's own
//!      estimate (its own occlusion rays) witnesses a deviation, split for if it contradicts the link's spread
//!      beyond the bound per link, or if what the leaf reflects wrongly through it exceeds `epsilon` times the
//!      leaf's reflected radiosity (dim leaves beside an occluder, which the absolute bound leaves coarse).
//!
//!   A link whose ends are both at the resolution limit (`min_area_fraction` of the scene's area) is kept and
//!   counted; refinement that would pass the node or link limit stops with an error.
//! - **Pieces** (`pieces`). What a pair is refined into depends on the pair alone (random streams are keyed by
//!   the nodes' keys, which name a node by its place in the tree, not by when it was made), so every refinement
//!   can run in independent pieces split by receiver subtree, each on its own copy of the tree, and merge into
//!   what one piece makes: new nodes and links are put in an order that depends on what they are
//!   ([`HierarchyOptions::pieces`]; a test merges 2, 3 and 7 pieces bit for bit into the one-piece answer).
//! - **Solve** (`solve`): Jacobi sweeps with push-pull, each pass's starting from the pass before's answer (new
//!   nodes at their parent's), or (`shoot`, [`HierarchySolver::Shooting`]) progressive refinement: the nodes with
//!   the most unshot power shoot over their links. Passes alternate solve and refinement until no link is split
//!   or the passes run out.
//! - **Claimed error**. After the last solve, each leaf's chain charge `c` (what it may gather wrongly per bounce)
//!   is propagated through the same operator, `e = c + rho H e`: the oracle's claimed bound on each leaf's
//!   radiosity error ([`HierarchicalSolution::error_bound`]), against which the tests judge the answer.
//!
//! # Closed scenes
//! In a closed scene every point's hemisphere is covered, so every leaf's total form factor (its row sum: the
//! links on its chain, pushed down) is 1, but the hierarchy's is not: an ancestor's link carries the ancestor's
//! average form factor, which overstates what a leaf in a corner sees and understates what a leaf facing the
//! middle sees. With reflectances near 1 that error is multiplied by `1 / (1 - rho)`: the white furnace at rho
//! 0.99 (`B = E / (1 - rho)` exactly) gathered more than its light per bounce at its corners and diverged. So, as the
//! flat path closes a closed scene's rows (`formfactor`, "Closure and open scenes"), the solves divide what each
//! leaf gathers by its row sum: the same test decides (escape rays, here [`CLOSURE_RAYS`] spread over the face
//! polygons by area; none may escape), the scene is never scaled if any does, and the stats say when it was. For
//! the furnace that is exact (a uniform `B` gathers `B` times the row sum); elsewhere it removes the row sums'
//! deviation as a common factor of what a leaf gathers, where the link that caused it may have been one of many.
//! The device tables (`bake::hier`) do not carry that factor: they close each leaf's row with its links (scaled
//! down where the row is over 1, both directions, and a link to itself where it is under), so that a closed
//! table's chains send on all the power they hold and the furnace is exact there too.
//!
//! # Status
//! The command line's default for the f64 answers of `solve`, `render`, `lightmap` and `export` (with
//! [`Refinement::Brightness`]; these options' own default stays [`Refinement::Budgets`]), and the table of `bake`
//! and `check` with `--method hierarchical` or, by default, for a scene whose flat mesh has no room for its faces
//! ([`crate::pipeline::flat_mesh_has_room`]) (links refined for the default light intensities; the answer is also
//! split by light source, [`HierarchicalSolution::transfer`]). Scenes with many small, nearly touching surfaces
//! (`scenes/make_office.py`) need many links per leaf: a cluster link is charged its whole transfer (isotropic
//! reception, an average radiosity sent), so where light is bright, links reach the surfaces, and the budget
//! passes push them down to the leaves; links grow much faster than leaves, and a refinement that would exceed
//! [`HierarchyOptions::max_links`] stops with [`HierarchyError::TooManyLinks`] (the full office solves only at a
//! coarse epsilon with a raised limit; the closing notes of issue 18 have the measurements). A cluster link between nearby nodes whose point-pair
//! estimate is untrustworthy is split at its cluster end rather than trusted; an iteration that diverges anyway
//! is reported as [`HierarchyError::NotConverged`].

//! # Files
//! `tree` (nodes, clusters, splits, sampling) -> `span` (what a solve tells refinement about the leaves below a
//! node) -> `excess` (chains that gather more than 1) -> `shaft` (whether anything can be between two surfaces)
//! -> `link` (estimates, the per-link oracle, pair refinement) -> `pieces` (refinement split by receiver subtree
//! and merged) -> `shadow` (links a leaf's own visibility contradicts) -> `solve` (push-pull iteration, error
//! propagation) and `shoot` (progressive refinement over links) -> `budget` (per-leaf charges, budget refinement)
//! -> `network` (the solved tree and links as public data, [`LinkNetwork`]) -> this module (options, the driver,
//! results); `dense` (the dense f64 answer on the leaves, [`dense_on_leaves`]: what the hierarchy is judged
//! against).

mod budget;
mod dense;
mod excess;
mod link;
mod network;
mod pieces;
mod shadow;
mod shaft;
mod shoot;
mod solve;
mod span;
#[cfg(test)]
mod testing;
mod tree;

use std::fmt;

use crate::formfactor::{
    escape_test, occluder_scene, ClosureMode, ElementRules, FormFactorError, FormFactorOptions,
};
use crate::lighting::PatchLighting;
use crate::mesh::{mesh, MeshError, MeshOptions, RepairReport};
use crate::patch::Patch;
use crate::raycast::RayCaster;
use crate::reference::TransferVectors;
use crate::rgb::{max_channel, Rgb};
use crate::scene::Scene;

pub use dense::{dense_on_leaves, DenseError};
pub use network::{LinkNetwork, NetworkLink, NetworkNode};

use link::{expand_self, link_error, split_either, split_link, Estimator, Limits, Link, RefineCounts};
use pieces::refine;
use rayon::prelude::*;
use span::Span;
use tree::{Kind, Tree};

/// Default error budget per element, relative to its reflected radiosity.
pub const DEFAULT_EPSILON: f64 = 0.03;
/// The direct-light stage's error bound per link, as a share of `epsilon` times the brightest face polygon's
/// emitted power.
pub const LINK_SHARE: f64 = 0.01;
/// Default most links (accepted and pending together) before refinement stops with
/// [`HierarchyError::TooManyLinks`]: a link costs a few hundred bytes at the peak of refinement (the link, its
/// estimate, the budgets' ledger), so this keeps a solve within a few GiB.
pub const DEFAULT_MAX_LINKS: usize = 10_000_000;
/// Default smallest element area, relative to the scene's total surface area.
pub const DEFAULT_MIN_AREA_FRACTION: f64 = 1e-5;
/// Default limit on tree nodes.
pub const DEFAULT_MAX_NODES: usize = 2_000_000;
/// Default point pairs (and shadow rays) of a link with a cluster at one end.
pub const DEFAULT_CLUSTER_SAMPLES: usize = 32;
/// Default receiver-subtree pieces of refinement (in place).
pub const DEFAULT_PIECES: usize = 1;
/// Default refinement passes (each but the last followed by a re-check against the solved radiosity).
pub const DEFAULT_PASSES: usize = 4;
/// [`HierarchyOptions::sender_weight`] of the command line's f64 answers (`solve`, `render`, `lightmap`,
/// `export`): the sender's unevenness charged 16 times its bound. The bound itself (weight 1) changes little,
/// because the brightness term it is added to is far looser wherever a link's form factor varies over its
/// receiver; a larger weight makes the sender term decide where the receiver sees an uneven sender evenly. The
/// weight is a choice made by measurement, not derived: the per-face error against links and seconds on the
/// Cornell box (`bench/REPORT.md`, "Hierarchy against flat", the rows with and without it).
pub const ANSWER_SENDER_WEIGHT: f64 = 16.0;
/// [`FormFactorOptions::samples_per_patch`] of the command line's f64 answers (`solve`, `render`, `lightmap`,
/// `export`): a 2 x 2 Gauss rule on each element (and on each piece of the near-field splitting) instead of the
/// flat estimator's 4 x 4. A link's form factor only has to be right to well within what the oracle lets the link
/// get wrong, and the 4 x 4 rule's extra accuracy is far below that: the kernel evaluations of the quadrature
/// were the largest part of refinement's time. A choice made by measurement: the Cornell box's faces against
/// both rules (`bench/REPORT.md`, "Hierarchy against flat"; a test holds the change within the hierarchy's own
/// claimed bound).
pub const ANSWER_SAMPLES_PER_PATCH: usize = 4;
/// Default relative change at which the push-pull iteration stops.
pub const DEFAULT_SOLVE_TOLERANCE: f64 = 1e-7;
/// Most push-pull sweeps of one solve.
pub const MAX_SWEEPS: usize = 100_000;

/// Escape rays of the closure test on the face polygons ([`escape_test`], spread by area): what the flat path's
/// test casts from a mesh of about a thousand patches, so that a polygon gets as many as its patches would.
pub const CLOSURE_RAYS: usize = 65_536;

/// How the linear system on the links is solved (both reach the same answer; see the tests of `shoot`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HierarchySolver {
    /// Jacobi sweeps over all links with push-pull (`solve`).
    #[default]
    Gathering,
    /// Progressive refinement: rounds in which the nodes with the most unshot power shoot over their links
    /// (`shoot`), the order a device relights in.
    Shooting,
}

/// What the passes after the first (the direct-light pass) refine for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Refinement {
    /// Every element's gathering error within `epsilon` of its own reflected radiosity (`budget`): accurate
    /// everywhere, dark corners included, at the cost of many links per element (chains refined down to the
    /// leaves).
    #[default]
    Budgets,
    /// The direct-light pass's rule again with the solved radiosity (brightness-weighted refinement iterated,
    /// Hanrahan, Salzman, Aupperle 1991): every link's power error within `epsilon * LINK_SHARE` of the brightest
    /// face polygon's emitted power. An absolute bound, so dim regions keep coarse links: far fewer links per
    /// element (device tables; a test checks fewer than half), with larger relative errors where the light is dim.
    Brightness,
}

/// Settings of the hierarchical solver.
#[derive(Clone, Debug)]
pub struct HierarchyOptions {
    /// Error budget per element, relative to its reflected radiosity (`--epsilon`); the direct-light stage's
    /// bound per link is `epsilon * LINK_SHARE` times the brightest face polygon's emitted power.
    pub epsilon: f64,
    /// Surfaces are not split below this fraction of the scene's surface area.
    pub min_area_fraction: f64,
    /// Most tree nodes: refinement that would make more stops with [`HierarchyError::TooManyNodes`].
    pub max_nodes: usize,
    /// Most links: refinement that would hold more (accepted and pending together) stops with
    /// [`HierarchyError::TooManyLinks`] instead of exhausting memory.
    pub max_links: usize,
    /// Point pairs of a link with a cluster at one end.
    pub cluster_samples: usize,
    /// Refinement passes.
    pub passes: usize,
    /// Relative change `sum A |dB| / sum A B` at which the gathering iteration stops; for shooting, the unshot
    /// power over the total at which it stops.
    pub solve_tolerance: f64,
    /// Gathering or shooting.
    pub solver: HierarchySolver,
    /// What the passes after the direct-light pass refine for.
    pub refinement: Refinement,
    /// The form-factor estimator's rules (samples per element, rays per pair, seed) for surface pairs, and its
    /// closure test (`closure`: with [`ClosureMode::Detect`], a closed scene's leaves gather to their row sums,
    /// module docs "Closed scenes"; [`ClosureMode::Off`] never scales).
    pub form_factors: FormFactorOptions,
    /// Receiver-subtree pieces every refinement runs in, each on its own copy of the tree, in parallel
    /// (`pieces`). The answer is the same, bit for bit, for every count: this is the split a run on several
    /// machines will use. On one machine 1 (in place) is as fast: the estimates within each wave of pairs run
    /// in parallel anyway, and each further piece copies the tree.
    pub pieces: usize,
    /// Print one line per pass on stderr.
    pub progress: bool,
    /// Shaft culling of surface pairs (Haines and Wallace 1991): where no face polygon reaches into the convex
    /// hull of a pair, the pair sees itself wholly and casts no ray, and its visible fraction is exact (no ray
    /// count's resolution in its spread). Requires that the caster hold no occluders but the face polygons
    /// solved (as [`solve_hierarchical`]'s does); `false` casts rays for every pair (to measure what culling
    /// changes).
    pub shaft_culling: bool,
    /// Weight of the sender's unevenness in the brightness oracle (the direct-light pass and
    /// [`Refinement::Brightness`]): a link between two surfaces is also charged this many times `F_rs` times the
    /// range of the sender's leaves' radiosity, the most its average can be off for a receiver point (`link`,
    /// `link_error`). 0 (the default) is the brightness oracle alone; the command line's f64 answers use
    /// [`ANSWER_SENDER_WEIGHT`].
    pub sender_weight: f64,
}

impl Default for HierarchyOptions {
    fn default() -> Self {
        HierarchyOptions {
            epsilon: DEFAULT_EPSILON,
            min_area_fraction: DEFAULT_MIN_AREA_FRACTION,
            max_nodes: DEFAULT_MAX_NODES,
            max_links: DEFAULT_MAX_LINKS,
            cluster_samples: DEFAULT_CLUSTER_SAMPLES,
            passes: DEFAULT_PASSES,
            solve_tolerance: DEFAULT_SOLVE_TOLERANCE,
            solver: HierarchySolver::Gathering,
            refinement: Refinement::Budgets,
            form_factors: FormFactorOptions { progress: false, ..FormFactorOptions::default() },
            pieces: DEFAULT_PIECES,
            progress: false,
            shaft_culling: true,
            sender_weight: 0.0,
        }
    }
}

/// Why the hierarchical solve could not run.
#[derive(Debug, thiserror::Error)]
pub enum HierarchyError {
    /// An option is out of range.
    #[error("invalid hierarchy option {name}: {problem}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// Nothing emits: the error bound (relative to the brightest emitter) is undefined, and the answer is zero.
    #[error("the scene emits no light (no face has a material with Ke > 0 in an enabled light group)")]
    NoEmission,
    /// Meshing or splitting failed.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The estimator's rules or the occluders could not be set up.
    #[error(transparent)]
    FormFactor(#[from] FormFactorError),
    /// Refinement would hold more links than [`HierarchyOptions::max_links`]: stopped before memory runs out.
    #[error(
        "refinement pass {pass} needs more than {limit} links ({links} accepted and {pending} pairs pending, at \
         {leaves} leaves); {} of the {split} links split so far were cluster links whose estimate could not be \
         trusted (surfaces nearly touching: the kernel 1/r^2 is heavy-tailed there), the rest were split for \
         their error bound. {}",
        percent(*untrusted, *split),
        if *untrusted * 2 > *split {
            "A larger --epsilon does not help against the first kind; move nearly touching surfaces apart or \
             join them, or allow more links (--max-links) if memory allows (a few hundred bytes per link)"
        } else {
            "Raise --epsilon, or allow more links (--max-links) if memory allows (a few hundred bytes per link)"
        }
    )]
    TooManyLinks {
        /// The limit.
        limit: usize,
        /// Links accepted when refinement stopped.
        links: usize,
        /// Pairs waiting to be estimated.
        pending: usize,
        /// Leaves of the tree then.
        leaves: usize,
        /// Links split so far.
        split: u64,
        /// Of those, cluster links split because their estimate could not be trusted.
        untrusted: u64,
        /// The refinement pass (1 is the direct-light pass).
        pass: usize,
    },
    /// Refinement would make more tree nodes than [`HierarchyOptions::max_nodes`].
    #[error(
        "refinement pass {pass} needs more than {limit} tree nodes (it had {nodes}); raise --epsilon (the limit \
         keeps the tree within memory: a node holds its polygon and quadrature points)"
    )]
    TooManyNodes {
        /// The limit.
        limit: usize,
        /// Nodes when refinement stopped.
        nodes: usize,
        /// The refinement pass (1 is the direct-light pass).
        pass: usize,
    },
    /// The iteration did not reach its tolerance.
    #[error("{}", not_converged(*sweeps, *change, *gain))]
    NotConverged {
        /// Sweeps run.
        sweeps: usize,
        /// Relative change of the last sweep.
        change: f64,
        /// The largest `max_c rho_c` times row sum over the leaves.
        gain: f64,
    },
}

/// The message of [`HierarchyError::NotConverged`].
fn not_converged(sweeps: usize, change: f64, gain: f64) -> String {
    let how = if change.is_finite() {
        format!("relative change {change:.3e} after {sweeps} sweeps")
    } else {
        format!("the radiosity grew without bound (it overflowed after {sweeps} sweeps)")
    };
    let why = if gain >= 1.0 {
        " (at 1 or above, light can grow without bound: with reflectances this close to 1, the hierarchy's \
         averaged form factors overstate what corner elements see by too much; a closed scene's gathered light is \
         scaled to its row sums, which removes that, but escape rays found an opening in this one, or closure is \
         off; --method flat keeps every pair's own form factor)"
    } else {
        ""
    };
    format!(
        "the push-pull iteration did not converge: {how}; the largest gain of a leaf (its reflectance times its \
         total form factor, its links' and its ancestors') is {gain:.5}{why}"
    )
}

/// `part` as a percentage of `whole`, for messages.
fn percent(part: u64, whole: u64) -> String {
    if whole == 0 {
        "none".to_owned()
    } else {
        format!("{:.1}%", 100.0 * part as f64 / whole as f64)
    }
}

/// One refinement pass.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PassStats {
    /// Links after the pass.
    pub links: usize,
    /// Leaves after the pass.
    pub leaves: usize,
    /// Tree nodes after the pass.
    pub nodes: usize,
    /// Pairs estimated in the pass.
    pub estimated: u64,
    /// Links split in the pass.
    pub split: u64,
    /// Of those, the cluster links split because their estimate could not be trusted (nearly touching
    /// surfaces), whatever their brightness.
    pub untrusted: u64,
    /// Occlusion rays cast in the pass.
    pub rays: u64,
}

/// What the hierarchical solve did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HierarchyStats {
    /// Face polygons (tree roots).
    pub polygons: usize,
    /// Cluster nodes.
    pub clusters: usize,
    /// Surface nodes (polygons and their pieces).
    pub surfaces: usize,
    /// Leaves (the elements the answer is given on).
    pub leaves: usize,
    /// Links between two surfaces.
    pub surface_links: usize,
    /// Links with a cluster at one end or both.
    pub cluster_links: usize,
    /// Links kept above the bound because neither end could be split (resolution or node limit).
    pub at_limit: u64,
    /// Occlusion rays cast.
    pub rays: u64,
    /// Pairs estimated.
    pub estimated: u64,
    /// One entry per pass.
    pub passes: Vec<PassStats>,
    /// The direct-light stage's error bound per link (W): `epsilon * LINK_SHARE * brightest_power`.
    pub threshold: f64,
    /// The brightest face polygon's emitted power, `A * max_c E` (W).
    pub brightest_power: f64,
    /// The oracle's claimed error, relative: the leaves' propagated error bounds over their radiosity
    /// (`sum A e / sum A max_c B`); `None` if the bound diverges (a leaf's `rho` times its total form factor
    /// reaches 1).
    pub claimed_error: Option<f64>,
    /// Push-pull sweeps of the last solve (gathering, which starts from the answer of the pass before), or its
    /// shots (shooting, from the emission).
    pub sweeps: usize,
    /// Smallest and largest total form factor a leaf gathers through (its links and its ancestors'): the
    /// hierarchy's row sums, 1 in a closed scene.
    pub row_sums: (f64, f64),
    /// Whether the scene was found closed (no escape ray, [`CLOSURE_RAYS`]), so that the solves scaled what each
    /// leaf gathers by one over its row sum (module docs, "Closed scenes").
    pub closed: bool,
}

impl fmt::Display for HierarchyStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} polygons -> {} leaves ({} clusters, {} surface nodes), {} links ({} surface-surface, {} with a \
             cluster), {} pairs estimated, {} rays, {} passes, row sums {:.5} .. {:.5}, claimed error {}",
            self.polygons,
            self.leaves,
            self.clusters,
            self.surfaces,
            self.surface_links + self.cluster_links,
            self.surface_links,
            self.cluster_links,
            self.estimated,
            self.rays,
            self.passes.len(),
            self.row_sums.0,
            self.row_sums.1,
            self.claimed_error.map_or_else(|| "unbounded".to_owned(), |e| format!("{e:.2e}"))
        )?;
        if self.at_limit > 0 {
            write!(f, "; {} links above the bound at the resolution or node limit", self.at_limit)?;
        }
        if self.closed {
            write!(f, "; closed scene (no escape ray): each leaf's gathered light divided by its row sum")?;
        }
        Ok(())
    }
}

/// The answer on the leaves of the hierarchy.
#[derive(Clone, Debug)]
pub struct HierarchicalSolution {
    /// The leaves as patches (each keeps its face), ordered by face, then by when they were made.
    pub leaves: Vec<Patch>,
    /// Reflectance per leaf.
    pub rho: Vec<Rgb>,
    /// Emission per leaf (W/m^2).
    pub emission: Vec<Rgb>,
    /// Radiosity per leaf (W/m^2).
    pub b: Vec<Rgb>,
    /// The oracle's claimed bound on each leaf's radiosity error (W/m^2, largest channel), or `None` if it
    /// diverges.
    pub error_bound: Option<Vec<f64>>,
    /// The part of [`Self::error_bound`] that does not average out over an area: the sender-side and random
    /// charges propagated alone. A link's receiver-side deviations sum to zero over its receiver (its form
    /// factor is their area average), so to first order an area average of radiosity (a face's, say) is off by
    /// at most the area average of this (W/m^2, largest channel).
    pub average_error_bound: Option<Vec<f64>>,
    /// The answer split by light source, on the same leaves (see [`solve_hierarchy_sources`]): the static
    /// emission's radiosity and one vector per dynamic light group at unit intensity, so that
    /// [`TransferVectors::relight`] gives the radiosity at any intensities without a new solve. The links were
    /// refined for the emission the solve was given (the default intensities), so other intensities are solved
    /// on links chosen for those. `None` when no sources were given.
    pub transfer: Option<TransferVectors>,
    /// The tree and links the answer was solved on (leaves point back into [`Self::leaves`]): what a device
    /// table is written from.
    pub network: LinkNetwork,
    /// What it took.
    pub stats: HierarchyStats,
    /// Wall time of link construction (seconds): the tree, every pair's estimate and the splits of every pass,
    /// without the solves between the passes and after the last. Kept out of [`Self::stats`], which is the same
    /// for every run of the same options.
    pub refine_seconds: f64,
}

/// Solves `scene` hierarchically with every light group at its default intensity, with Embree occluders; the
/// answer is also split by light source ([`HierarchicalSolution::transfer`]: the static lights, then the scene's
/// dynamic groups in order).
///
/// # Errors
/// See [`solve_hierarchy`]; also meshing and occluder errors.
pub fn solve_hierarchical(
    scene: &Scene,
    options: &HierarchyOptions,
) -> Result<HierarchicalSolution, HierarchyError> {
    solve_hierarchical_noting(scene, options, |_| {})
}

/// [`solve_hierarchical`], handing what mesh repair changed to `repaired` once the roots are meshed and before
/// any refinement (not called when the scene's meshing turns repair off), so that a caller can report it without
/// repairing the scene a second time.
///
/// # Errors
/// As [`solve_hierarchical`].
pub fn solve_hierarchical_noting(
    scene: &Scene,
    options: &HierarchyOptions,
    repaired: impl FnOnce(&RepairReport),
) -> Result<HierarchicalSolution, HierarchyError> {
    check_options(options)?;
    let meshed = mesh(scene, &MeshOptions { patch_budget: usize::MAX, ..MeshOptions::no_subdivide(scene) })?;
    if let Some(report) = &meshed.repair {
        repaired(report);
    }
    let roots = meshed.patches;
    let lighting = PatchLighting::new(scene, &roots);
    let caster = occluder_scene(&roots, true)?;
    let mut sources = vec![lighting.static_emission.clone()];
    for g in 0..lighting.dynamic_groups.len() {
        sources.push(
            (0..roots.len())
                .map(|k| if lighting.group[k] == Some(g) { lighting.unit_emission[k] } else { Rgb::ZERO })
                .collect(),
        );
    }
    solve_hierarchy_sources(&roots, &lighting.rho, &lighting.default_emission(), &sources, &caster, options)
}

impl HierarchyOptions {
    /// Checks every option's range, as the solves do before any work; callers that load or repair a scene first
    /// call it before that, so that a bad option is reported at once.
    ///
    /// # Errors
    /// [`HierarchyError::InvalidOption`] naming the first option out of range.
    pub fn validate(&self) -> Result<(), HierarchyError> {
        check_options(self)
    }
}

/// See [`HierarchyOptions::validate`].
fn check_options(options: &HierarchyOptions) -> Result<(), HierarchyError> {
    let bad = |name, problem: &str| Err(HierarchyError::InvalidOption { name, problem: problem.to_owned() });
    if !(options.epsilon > 0.0 && options.epsilon < 1.0) {
        return bad("epsilon", "must be in (0, 1): a relative error budget per element");
    }
    if !(options.min_area_fraction >= 0.0 && options.min_area_fraction < 1.0) {
        return bad("min_area_fraction", "must be in [0, 1)");
    }
    if options.cluster_samples < 2 {
        return bad("cluster_samples", "must be at least 2 (the standard error needs two)");
    }
    if options.max_links == 0 {
        return bad("max_links", "must be at least 1");
    }
    if options.passes == 0 {
        return bad("passes", "must be at least 1");
    }
    if options.pieces == 0 {
        return bad("pieces", "must be at least 1");
    }
    if !(options.solve_tolerance > 0.0 && options.solve_tolerance < 1.0) {
        return bad("solve_tolerance", "must be in (0, 1)");
    }
    if !(options.sender_weight >= 0.0 && options.sender_weight.is_finite()) {
        return bad("sender_weight", "must be a finite number, 0 or more");
    }
    Ok(())
}

/// Solves the scene made of `roots` (one patch per face polygon, with reflectance `rho` and emission `emission`
/// per polygon) hierarchically, casting occlusion rays at `caster`. With [`HierarchyOptions::shaft_culling`] (the
/// default) no ray is cast between two surfaces that no polygon of `roots` can come between, so `caster` must
/// hold no occluders but (some of) `roots`.
///
/// # Errors
/// [`HierarchyError::InvalidOption`] for an option out of range or fewer node slots than the tree over `roots`
/// needs, [`HierarchyError::NoEmission`] if nothing emits, [`HierarchyError::NotConverged`] if an iteration does
/// not converge, [`HierarchyError::Mesh`] if a split degenerates.
///
/// # Panics
/// If `rho` or `emission` is shorter than `roots`.
pub fn solve_hierarchy<C: RayCaster + ?Sized>(
    roots: &[Patch],
    rho: &[Rgb],
    emission: &[Rgb],
    caster: &C,
    options: &HierarchyOptions,
) -> Result<HierarchicalSolution, HierarchyError> {
    solve_hierarchy_sources(roots, rho, emission, &[], caster, options)
}

/// [`solve_hierarchy`], and after it the same system solved once per light source on the final links:
/// `sources[0]` is the emission per face polygon of the static lights, `sources[1..]` each dynamic group's at
/// unit intensity ([`HierarchicalSolution::transfer`]; none if `sources` is empty).
///
/// # Errors
/// As [`solve_hierarchy`]; [`HierarchyError::InvalidOption`] if a source does not have one emission per
/// polygon; [`HierarchyError::NotConverged`] if a source's solve does not converge.
pub fn solve_hierarchy_sources<C: RayCaster + ?Sized>(
    roots: &[Patch],
    rho: &[Rgb],
    emission: &[Rgb],
    sources: &[Vec<Rgb>],
    caster: &C,
    options: &HierarchyOptions,
) -> Result<HierarchicalSolution, HierarchyError> {
    check_options(options)?;
    if let Some(k) = sources.iter().position(|s| s.len() != roots.len()) {
        return Err(HierarchyError::InvalidOption {
            name: "sources",
            problem: format!("source {k} has {} emissions for {} polygons", sources[k].len(), roots.len()),
        });
    }
    match options.form_factors.threads {
        Some(threads) => rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| HierarchyError::InvalidOption { name: "threads", problem: e.to_string() })?
            .install(|| solve_checked(roots, rho, emission, sources, caster, options)),
        None => solve_checked(roots, rho, emission, sources, caster, options),
    }
}

/// [`solve_hierarchy`] after the option checks, on the current thread pool.
fn solve_checked<C: RayCaster + ?Sized>(
    roots: &[Patch],
    rho: &[Rgb],
    emission: &[Rgb],
    sources: &[Vec<Rgb>],
    caster: &C,
    options: &HierarchyOptions,
) -> Result<HierarchicalSolution, HierarchyError> {
    if options.max_nodes < 2 * roots.len() {
        return Err(HierarchyError::InvalidOption {
            name: "max_nodes",
            problem: format!(
                "{} is fewer than the {} nodes of the tree over {} polygons",
                options.max_nodes,
                2 * roots.len() - 1,
                roots.len()
            ),
        });
    }
    let brightest_power =
        roots.iter().zip(emission).map(|(p, e)| p.area * max_channel(*e)).fold(0.0, f64::max);
    if brightest_power <= 0.0 || !brightest_power.is_finite() {
        return Err(HierarchyError::NoEmission);
    }
    let rules = ElementRules::new(&options.form_factors)?;
    let progress = link::Progress::new();
    let mut refining = std::time::Instant::now();
    // Closure is a property of the scene: tested once, on the face polygons (module docs, "Closed scenes").
    let closed = match options.form_factors.closure {
        ClosureMode::Detect => {
            let (cast, escaped) = escape_test(roots, caster, options.form_factors.seed, CLOSURE_RAYS);
            cast > 0 && escaped == 0
        }
        ClosureMode::Off => false,
    };
    let mut refine_time = std::time::Duration::ZERO;
    let mut tree = Tree::new(&rules, roots, rho, emission);
    let total_area: f64 = roots.iter().map(|p| p.area).sum();
    let limits = Limits {
        threshold: options.epsilon * LINK_SHARE * brightest_power,
        min_area: options.min_area_fraction * total_area,
        max_nodes: options.max_nodes,
        max_links: options.max_links,
        pieces: options.pieces,
        sender_weight: options.sender_weight,
    };
    let estimator = Estimator {
        rules: &rules,
        caster,
        cluster_samples: options.cluster_samples,
        seed: options.form_factors.seed,
        shafts: options.shaft_culling,
        progress: options.progress.then_some(&progress),
    };
    let mut spans = solve::emission_bound(&tree);
    let mut links = Vec::new();
    let mut candidates = Vec::new();
    expand_self(&tree, 0, &mut candidates);
    let mut counts = RefineCounts::default();
    let mut leaf_estimates = shadow::LeafEstimates::default();
    let mut passes = Vec::new();
    let mut solution;
    let mut system;
    let mut solution_b: Vec<Rgb> = Vec::new();
    loop {
        let before = counts;
        let pass = passes.len() + 1;
        let in_pass = |e: HierarchyError| match e {
            HierarchyError::TooManyLinks { limit, links, pending, leaves, split, untrusted, .. } => {
                HierarchyError::TooManyLinks { limit, links, pending, leaves, split, untrusted, pass }
            }
            HierarchyError::TooManyNodes { limit, nodes, .. } => {
                HierarchyError::TooManyNodes { limit, nodes, pass }
            }
            e => e,
        };
        if passes.is_empty() {
            refine(
                &mut tree,
                &estimator,
                &mut spans,
                &limits,
                std::mem::take(&mut candidates),
                &mut links,
                &mut counts,
            )
            .map_err(in_pass)?;
        } else {
            refining = std::time::Instant::now();
            let (t, e, s, l, c) = (&mut tree, &estimator, &mut spans, &limits, &mut counts);
            match options.refinement {
                Refinement::Budgets => budget::refine_budgets(t, e, s, l, options.epsilon, &mut links, c),
                Refinement::Brightness => {
                    refine_brightness_pass(t, e, s, l, options.epsilon, &mut links, c, &mut leaf_estimates)
                }
            }
            .map_err(in_pass)?;
        }
        refine_time += refining.elapsed();
        // Warm from the last pass's answer: refinement changes it little, and the sweeps then settle sooner.
        let warm = (!passes.is_empty()).then_some(solution_b.as_slice());
        system = System::new(&tree, &links, closed);
        solution = solve_with(&tree, &links, &system, &solve::emission(&tree), options, warm)?;
        solution_b.clone_from(&solution.b);
        let leaves = tree.nodes.iter().filter(|n| n.children.is_empty()).count();
        passes.push(PassStats {
            links: links.len(),
            leaves,
            nodes: tree.nodes.len(),
            estimated: counts.estimated - before.estimated,
            split: counts.split - before.split,
            untrusted: counts.untrusted - before.untrusted,
            rays: counts.rays - before.rays,
        });
        if let (true, Some(p)) = (options.progress, passes.last()) {
            eprintln!(
                "hierarchy pass {} ({}): {} pairs estimated, {} split ({} of them untrusted cluster estimates), {} \
                 rays -> {} leaves, {} links",
                passes.len(),
                match (passes.len(), options.refinement) {
                    (1, _) => "direct light",
                    (_, Refinement::Budgets) => "budgets",
                    (_, Refinement::Brightness) => "brightness",
                },
                p.estimated,
                p.split,
                p.untrusted,
                p.rays,
                p.leaves,
                p.links
            );
        }
        spans = solution.spans.clone();
        // The budget passes end when one splits nothing (its solve then only confirmed the last).
        if passes.len() == options.passes || (passes.len() > 1 && counts.split == before.split) {
            break;
        }
    }
    let (charges, persistent) = budget::leaf_charges(&tree, &spans, &limits, &links, options.epsilon);
    let propagate = |c: &[f64]| {
        solve::propagate(&tree, &system.incoming, (c, &system.rho), options.solve_tolerance, MAX_SWEEPS)
    };
    let bound = propagate(&charges).zip(propagate(&persistent));
    let mut out =
        finish(&tree, &links, &solution, bound, counts, passes, &limits, brightest_power, roots.len());
    out.refine_seconds = refine_time.as_secs_f64();
    out.stats.closed = closed;
    if !sources.is_empty() {
        let order = leaf_order(&tree);
        let (mut residual, mut sweeps) = (0.0f64, 0);
        let mut per_source = Vec::with_capacity(sources.len());
        for source in sources {
            let e: Vec<Rgb> = tree
                .nodes
                .iter()
                .map(|n| if n.root == tree::NONE { Rgb::ZERO } else { source[n.root as usize] })
                .collect();
            let s = solve_with(&tree, &links, &system, &e, options, None)?;
            residual = residual.max(s.change);
            sweeps += s.sweeps;
            per_source.push(order.iter().map(|&k| s.b[k]).collect::<Vec<Rgb>>());
        }
        let b_static = per_source.remove(0);
        out.transfer = Some(TransferVectors { b_static, t: per_source, residual, sweeps });
    }
    Ok(out)
}

/// One pass of brightness refinement after a solve: `link::refine_brightness` with the links on the chain of
/// every leaf that gathers more than 1 in all (no tolerance: the device's table must cap whatever excess is left,
/// `excess`) and the links a leaf below them contradicts (`shadow`), split whatever their error. Returns the
/// links split. `known` carries the shadow check's leaf estimates from pass to pass.
///
/// # Errors
/// As `link::refine_brightness`.
#[allow(clippy::too_many_arguments)]
fn refine_brightness_pass<C: RayCaster + ?Sized>(
    tree: &mut Tree,
    estimator: &Estimator<'_, C>,
    spans: &mut Vec<span::Span>,
    limits: &Limits,
    epsilon: f64,
    links: &mut Vec<link::Link>,
    counts: &mut RefineCounts,
    known: &mut shadow::LeafEstimates,
) -> Result<u64, HierarchyError> {
    let mut split_at = excess::overstated(tree, links, 0.0);
    let shadowed = shadow::contradicted(tree, estimator, spans, limits.threshold, epsilon, links, known);
    counts.estimated += shadowed.estimated;
    counts.rays += shadowed.rays;
    split_at.extend(shadowed.links);
    split_at.sort_unstable();
    split_at.dedup_by_key(|o| o.0);
    refine_brightness(tree, estimator, spans, limits, &split_at, links, counts)
}

/// One pass of brightness-weighted refinement against the solved radiosity (Hanrahan, Salzman, Aupperle 1991,
/// iterated as in their paper): every link whose power error `link_error` under the current `spans` exceeds the
/// bound is replaced by the pairs of its larger splittable end, which are estimated and refined like the first
/// pass's; the others stay as they are (not estimated again). The links of `overstated` (`(index, end)`, sorted
/// by index, one per link: `excess::overstated`, `shadow::contradicted`) are split at that end whatever their
/// error. Returns the links split.
///
/// # Errors
/// [`HierarchyError::Mesh`] if a surface cannot be split.
fn refine_brightness<C: RayCaster + ?Sized>(
    tree: &mut Tree,
    estimator: &Estimator<'_, C>,
    spans: &mut Vec<Span>,
    limits: &Limits,
    overstated: &[(usize, u32)],
    links: &mut Vec<Link>,
    counts: &mut RefineCounts,
) -> Result<u64, HierarchyError> {
    let mut candidates = Vec::new();
    let mut kept = Vec::with_capacity(links.len());
    let mut split = 0;
    let mut next_overstated = overstated.iter().peekable();
    // Judged in parallel before any split (a split adds nodes, not links, so the judgement does not change).
    let above: Vec<bool> = {
        let (tree, spans) = (&*tree, &*spans);
        links
            .par_iter()
            .map(|l| link_error(tree, spans, l, limits.sender_weight) > limits.threshold)
            .collect()
    };
    for ((k, link), above) in links.drain(..).enumerate().zip(above) {
        let at = next_overstated.next_if(|o| o.0 == k).map(|o| o.1);
        let done = if let Some(end) = at {
            split_either(tree, estimator.rules, spans, limits, link.pair(tree), end, &mut candidates)?
        } else {
            above && split_link(tree, estimator.rules, spans, limits, link.pair(tree), &mut candidates)?
        };
        if done {
            split += 1;
            counts.split += 1;
        } else {
            kept.push(link);
        }
    }
    *links = kept;
    refine(tree, estimator, spans, limits, candidates, links, counts)?;
    Ok(split)
}

/// What every solve on one set of links reads besides the emission: the links grouped by receiver and the
/// reflectance per node ([`reflectance_of`]), made once for all of them.
struct System {
    incoming: solve::Incoming,
    rho: Vec<Rgb>,
}

impl System {
    fn new(tree: &Tree, links: &[link::Link], closed: bool) -> System {
        System {
            incoming: solve::Incoming::new(tree.nodes.len(), links),
            rho: reflectance_of(tree, links, closed),
        }
    }
}

/// The system on `links` (`on`: made from them) solved with emission `e` per node by the chosen solver;
/// gathering starts from `warm` (an earlier pass's radiosity per node) if given, shooting always from the
/// emission.
///
/// # Errors
/// [`HierarchyError::NotConverged`] if it does not reach the tolerance, diverges (NaN or infinity: some leaf
/// gathers more than it can reflect away) or runs out of sweeps.
fn solve_with(
    tree: &Tree,
    links: &[link::Link],
    on: &System,
    e: &[Rgb],
    options: &HierarchyOptions,
    warm: Option<&[Rgb]>,
) -> Result<solve::NodeRadiosity, HierarchyError> {
    let rho = &on.rho;
    let system = (e, rho.as_slice());
    let solution = match options.solver {
        HierarchySolver::Gathering => {
            solve::solve(tree, &on.incoming, system, warm, options.solve_tolerance, MAX_SWEEPS)
        }
        HierarchySolver::Shooting => shoot::shoot(tree, links, system, options.solve_tolerance, MAX_SWEEPS),
    };
    if solution.change.is_nan() || solution.change > options.solve_tolerance {
        let (sums, _) = excess::leaf_row_sums(tree, links);
        let gain = tree
            .nodes
            .iter()
            .zip(&sums)
            .zip(rho)
            .filter(|((n, _), _)| n.children.is_empty())
            .map(|((_, s), r)| r.max_element() * s)
            .fold(0.0, f64::max);
        return Err(HierarchyError::NotConverged { sweeps: solution.sweeps, change: solution.change, gain });
    }
    Ok(solution)
}

/// The reflectance the solves use per node: the surfaces' (zero on clusters), and in a closed scene each leaf's
/// divided by its total form factor (its row sum, [`excess::leaf_row_sums`]), so that what it gathers is scaled to
/// the whole hemisphere it sees (module docs, "Closed scenes"). A leaf without links keeps its own.
fn reflectance_of(tree: &Tree, links: &[link::Link], closed: bool) -> Vec<Rgb> {
    let mut rho = solve::reflectance(tree);
    if closed {
        let (sums, _) = excess::leaf_row_sums(tree, links);
        for ((r, node), s) in rho.iter_mut().zip(&tree.nodes).zip(&sums) {
            if node.children.is_empty() && *s > 0.0 {
                *r /= *s;
            }
        }
    }
    rho
}

/// The leaves' node indices in the answer's order: by face, then by node index (when they were made).
fn leaf_order(tree: &Tree) -> Vec<usize> {
    let mut leaves: Vec<(usize, usize)> = tree
        .nodes
        .iter()
        .enumerate()
        .filter_map(|(k, node)| match &node.kind {
            Kind::Surface { element, .. } if node.children.is_empty() => Some((element.patch().face, k)),
            _ => None,
        })
        .collect();
    leaves.sort_unstable();
    leaves.into_iter().map(|(_, k)| k).collect()
}

/// The leaves' answer and the statistics.
#[allow(clippy::too_many_arguments)]
fn finish(
    tree: &Tree,
    links: &[link::Link],
    solution: &solve::NodeRadiosity,
    bound: Option<(Vec<f64>, Vec<f64>)>,
    counts: RefineCounts,
    passes: Vec<PassStats>,
    limits: &Limits,
    brightest_power: f64,
    polygons: usize,
) -> HierarchicalSolution {
    let leaves = leaf_order(tree);
    let clusters = tree.nodes.iter().filter(|n| matches!(n.kind, Kind::Cluster { .. })).count();
    let surfaces = tree.nodes.len() - clusters;
    let (surface_links, cluster_links) = links.iter().fold((0, 0), |(s, c), l| {
        if tree.is_cluster(l.a) || tree.is_cluster(l.b) {
            (s, c + 1)
        } else {
            (s + 1, c)
        }
    });
    let mut out = HierarchicalSolution {
        leaves: Vec::with_capacity(leaves.len()),
        rho: Vec::with_capacity(leaves.len()),
        emission: Vec::with_capacity(leaves.len()),
        b: Vec::with_capacity(leaves.len()),
        error_bound: bound.as_ref().map(|_| Vec::with_capacity(leaves.len())),
        average_error_bound: bound.as_ref().map(|_| Vec::with_capacity(leaves.len())),
        transfer: None,
        network: LinkNetwork::default(),
        refine_seconds: 0.0,
        stats: HierarchyStats {
            polygons,
            clusters,
            surfaces,
            leaves: leaves.len(),
            surface_links,
            cluster_links,
            at_limit: counts.at_limit,
            rays: counts.rays,
            estimated: counts.estimated,
            passes,
            threshold: limits.threshold,
            brightest_power,
            claimed_error: None,
            sweeps: solution.sweeps,
            row_sums: excess::leaf_row_sums(tree, links).1,
            closed: false,
        },
    };
    let (mut radiosity, mut claimed) = (0.0, 0.0);
    for &k in &leaves {
        let node = &tree.nodes[k];
        if let Kind::Surface { element, rho, emission } = &node.kind {
            out.leaves.push(element.patch().clone());
            out.rho.push(*rho);
            out.emission.push(*emission);
            out.b.push(solution.b[k]);
            radiosity += node.area * max_channel(solution.b[k]);
            if let (Some((all, lasting)), Some(mine), Some(average)) =
                (&bound, &mut out.error_bound, &mut out.average_error_bound)
            {
                mine.push(all[k]);
                average.push(lasting[k]);
                claimed += node.area * all[k];
            }
        }
    }
    let mut leaf_index = vec![tree::NONE; tree.nodes.len()];
    for (i, &k) in leaves.iter().enumerate() {
        leaf_index[k] = i as u32;
    }
    out.network = LinkNetwork::new(tree, links, &leaf_index);
    if bound.is_some() {
        out.stats.claimed_error = Some(if radiosity > 0.0 { claimed / radiosity } else { 0.0 });
    }
    out
}
