//! The estimator's settings ([`FormFactorOptions`]) and the closure switch.

/// Cosine-distributed rays cast from each patch into its hemisphere to decide whether the scene is closed
/// ([`ClosureMode::Detect`]).
pub const ESCAPE_RAYS_PER_PATCH: usize = 64;

/// Whether to close the rows of a closed scene (see the module docs, "Closure and open scenes").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ClosureMode {
    /// Cast [`ESCAPE_RAYS_PER_PATCH`] rays from every patch; if none escapes the scene, it is closed and its rows
    /// are closed by rescaling the partly visible pairs only. Any escaping ray leaves every row as estimated.
    #[default]
    Detect,
    /// Never change rows (the raw estimate, e.g. to measure visibility noise).
    Off,
}

/// Settings of [`super::compute_form_factors`].
#[derive(Clone, Debug, PartialEq)]
pub struct FormFactorOptions {
    /// Sample points on each patch `i` (the outer quadrature): a Gauss-Legendre `n × n` rule with
    /// `n = round(sqrt(samples_per_patch))` on parallelograms, and on each fan triangle of other polygons.
    pub samples_per_patch: usize,
    /// Occlusion rays per pair `(i, j)` that estimate the visible fraction: from stratified points on `i` to
    /// stratified points on `j`.
    pub rays_per_pair: usize,
    /// Seed of all random numbers; equal seeds give identical matrices whatever the thread count.
    pub seed: u64,
    /// Show a progress bar on stderr (only when stderr is a terminal).
    pub progress: bool,
    /// Worker threads; `None` uses rayon's global pool.
    pub threads: Option<usize>,
    /// Build the Embree scene with `RTC_SCENE_FLAG_ROBUST` (watertight edges, slower).
    pub robust: bool,
    /// Whether to detect a closed scene and close its rows.
    pub closure: ClosureMode,
    /// Integrate pairs in the far field ([`super::FAR_FIELD_GAP`]) with the lower-order rule ([`super::far_field_order`]);
    /// `false` uses the full rule everywhere (to measure what the far-field rule changes).
    pub far_field: bool,
}

impl Default for FormFactorOptions {
    fn default() -> Self {
        Self {
            samples_per_patch: 16,
            rays_per_pair: 16,
            seed: 1,
            progress: true,
            threads: None,
            robust: true,
            closure: ClosureMode::Detect,
            far_field: true,
        }
    }
}
