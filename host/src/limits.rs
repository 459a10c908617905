//! The documented limit of every size a user gives (image sizes, patch budgets, sample and ray counts, threads,
//! frames, repetitions), checked before any work: a size beyond its limit gets a [`LimitError`] naming the option,
//! the value and the limit, instead of hours of work or an aborted allocation.
//!
//! Each limit is set by what the size costs:
//! - Pictures hold about 40 bytes per pixel while they are rendered (hit records, radiosity, colour):
//!   [`MAX_IMAGE_SIDE`] pixels on a side and [`MAX_IMAGE_PIXELS`] in all keep one picture under a gigabyte.
//! - Form factors cost time and up to `N²` entries of memory (13 bytes each) for `N` patches:
//!   [`MAX_PATCHES`] bounds the worst case near 3.5 GB (a typical scene stores far fewer entries).
//! - Per pair of patches, [`MAX_SAMPLES`] kernel evaluations and [`MAX_RAYS`] occlusion rays; beyond them the
//!   estimate stops improving measurably long before the run ends.
//! - [`MAX_PATHS`] paths per face for the continuous reference (`reference --samples` and `--max-samples`,
//!   `check --reference-samples`): 1024 times the default cap, and its standard error only falls as the square
//!   root of the paths.
//! - [`MAX_THREADS`] worker threads, [`MAX_REPS`] benchmark repetitions and [`MAX_FF_FACTOR`] for the
//!   form-factor component's reference; device frames per light setting are limited by
//!   [`crate::check::MAX_FRAMES`].

/// Largest width or height of a picture, in pixels.
pub const MAX_IMAGE_SIDE: u32 = 16_384;
/// Largest pixel count of a picture (4096 x 4096).
pub const MAX_IMAGE_PIXELS: u64 = 1 << 24;
/// Largest patch budget (`--max-patches`).
pub const MAX_PATCHES: usize = 16_384;
/// Largest number of sample points per patch (`--samples`).
pub const MAX_SAMPLES: usize = 1024;
/// Largest number of occlusion rays per pair of patches (`--rays`).
pub const MAX_RAYS: usize = 16_384;
/// Largest number of paths per face of the continuous reference (`reference --samples`, `--max-samples`;
/// `check --reference-samples`): 1024 times [`crate::montecarlo::DEFAULT_MAX_SAMPLES`].
pub const MAX_PATHS: u64 = 1 << 30;
/// Largest number of worker threads (`--threads`).
pub const MAX_THREADS: usize = 1024;
/// Largest number of repetitions of a timed run (`bench --reps`).
pub const MAX_REPS: usize = 100;
/// Largest multiple of samples and rays for the form-factor component's reference (`check --ff-factor`).
pub const MAX_FF_FACTOR: usize = 64;

/// A size outside its documented range.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{option} {value}: {problem}")]
pub struct LimitError {
    /// The option (as the command line spells it, e.g. `--width`).
    pub option: String,
    /// The value given.
    pub value: u64,
    /// What is wrong: the range, and why.
    pub problem: String,
}

/// Checks `1 <= value <= max` for `option`; `why` says what the limit protects.
///
/// # Errors
/// [`LimitError`] naming `option`, the value and the range.
pub fn check_count(option: &str, value: usize, max: usize, why: &str) -> Result<(), LimitError> {
    if (1..=max).contains(&value) {
        return Ok(());
    }
    Err(LimitError {
        option: option.to_owned(),
        value: value as u64,
        problem: format!("must be between 1 and {max} ({why})"),
    })
}

/// Checks a picture size against [`MAX_IMAGE_SIDE`] and [`MAX_IMAGE_PIXELS`]; `option` names the size's option(s).
///
/// # Errors
/// [`LimitError`] if a side is 0 or above the limit, or the picture has too many pixels.
pub fn check_image_size(option: &str, width: u32, height: u32) -> Result<(), LimitError> {
    let side = "about 40 bytes per pixel while rendering";
    for value in [width, height] {
        check_count(option, value as usize, MAX_IMAGE_SIDE as usize, side)?;
    }
    let pixels = u64::from(width) * u64::from(height);
    if pixels > MAX_IMAGE_PIXELS {
        return Err(LimitError {
            option: option.to_owned(),
            value: pixels,
            problem: format!(
                "{width} x {height} pixels are more than {MAX_IMAGE_PIXELS} (4096 x 4096; {side}, {:.1} GB here)",
                pixels as f64 * 40.0 / 1e9
            ),
        });
    }
    Ok(())
}
