//! What the solve tells refinement about the leaves below a node.

use crate::rgb::Rgb;

/// The brightness of the leaves below a node (per channel): range, area means and spread.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Span {
    /// Largest.
    pub(super) hi: Rgb,
    /// Smallest.
    pub(super) lo: Rgb,
    /// Area-mean reflected radiosity `B - E`.
    pub(super) reflected: Rgb,
    /// Area-mean radiosity.
    pub(super) mean: Rgb,
    /// Area-mean square of the leaves' radiosity.
    pub(super) square: Rgb,
}

impl Span {
    /// Every value zero.
    pub(super) const ZERO: Span =
        Span { hi: Rgb::ZERO, lo: Rgb::ZERO, reflected: Rgb::ZERO, mean: Rgb::ZERO, square: Rgb::ZERO };

    /// The area-weighted standard deviation of the leaves' radiosity.
    pub(super) fn deviation(&self) -> Rgb {
        (self.square - self.mean * self.mean).max(Rgb::ZERO).powf(0.5)
    }
}
