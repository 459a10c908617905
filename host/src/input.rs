//! [`InputError`]: the checks every numeric routine of the host runs on its slices (one entry per patch, every
//! value finite), shared by [`crate::metrics`] and [`crate::reference`] so both say the same thing.

use crate::rgb::Rgb;
use thiserror::Error;

/// A per-patch input slice that is the wrong length or holds NaN or infinity.
#[derive(Clone, Debug, PartialEq, Error)]
#[non_exhaustive]
pub enum InputError {
    /// An input slice has the wrong length.
    #[error("{what} has {found} entries, expected {expected}")]
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// A value is NaN or infinite.
    #[error("{what} of patch {patch}, channel {channel} is not finite ({value})")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Patch index.
        patch: usize,
        /// Channel (0 = R, 1 = G, 2 = B).
        channel: usize,
        /// The offending value.
        value: f64,
    },
}

/// Checks that `values` (named `what` in the error) has `n` entries.
///
/// # Errors
/// [`InputError::LengthMismatch`] if not.
pub fn check_len<T>(what: &'static str, values: &[T], n: usize) -> Result<(), InputError> {
    if values.len() == n {
        Ok(())
    } else {
        Err(InputError::LengthMismatch { what, expected: n, found: values.len() })
    }
}

/// Checks that every channel of every value of `values` (named `what` in the error) is finite.
///
/// # Errors
/// [`InputError::NonFinite`] naming the first patch and channel that is not.
pub fn check_finite(what: &'static str, values: &[Rgb]) -> Result<(), InputError> {
    for (patch, v) in values.iter().enumerate() {
        for (channel, value) in v.to_array().into_iter().enumerate() {
            if !value.is_finite() {
                return Err(InputError::NonFinite { what, patch, channel, value });
            }
        }
    }
    Ok(())
}
