//! The static base (crate docs, "Static base"): the radiosity a patch shows from the table's precomputed
//! static light, `E_s + rho G_s`. One function, used by the solver for patches without run-time state and by
//! the transfer relight for `B_static`.

use crate::codec::{decode_emission, decode_reflectance};
use crate::format::Table;
use crate::scalar::Scalar;

/// An emission or irradiance code as a solver number (exact: the code decodes to a dyadic value).
#[inline]
pub(crate) fn emission<S: Scalar>(code: u16) -> S {
    let (m, e) = decode_emission(code);
    S::from_dyadic(m, e)
}

/// `E_s + rho G_s` (W/m^2, RGB) of `patch` with reflectance codes `rho` (the table's or the solver's
/// current ones), or `None` out of range.
#[must_use]
pub(crate) fn static_radiosity_with<S: Scalar>(
    table: &Table<'_>,
    patch: u32,
    rho: [u16; 3],
) -> Option<[S; 3]> {
    Some(static_from_codes(table.base_emission(patch)?, table.base_irradiance(patch)?, rho))
}

/// `E_s + rho G_s` (W/m^2, RGB) from the emission, irradiance and reflectance codes (flat patches and
/// hierarchical leaves alike).
#[must_use]
#[inline]
pub(crate) fn static_from_codes<S: Scalar>(e: [u16; 3], g: [u16; 3], rho: [u16; 3]) -> [S; 3] {
    [0, 1, 2].map(|c| emission::<S>(e[c]).add(emission::<S>(g[c]).mul_frac(decode_reflectance(rho[c]))))
}

/// [`static_from_codes`], the reflectance codes read (by `rho`) only when the base is not zero: an element no
/// static light reaches (every code 0, the usual case when every light is dynamic) is `0` in any arithmetic,
/// bit for bit what the decode gives (`0 + rho 0`), without decoding anything.
#[must_use]
#[inline]
pub(crate) fn static_or_zero<S: Scalar>(
    e: [u16; 3],
    g: [u16; 3],
    rho: impl FnOnce() -> Option<[u16; 3]>,
) -> Option<[S; 3]> {
    if e == [0; 3] && g == [0; 3] {
        return Some([S::ZERO; 3]);
    }
    Some(static_from_codes(e, g, rho()?))
}

/// The static radiosity `B_static_i = E_s_i + rho_i G_s_i` (W/m^2, RGB) of `patch` from the table's static
/// base and reflectances (crate docs, "Static base"; the static solution when the base is solved), or `None`
/// out of range.
#[must_use]
pub fn static_radiosity<S: Scalar>(table: &Table<'_>, patch: u32) -> Option<[S; 3]> {
    let rho = || table.reflectance(table.material(patch)?);
    static_or_zero(table.base_emission(patch)?, table.base_irradiance(patch)?, rho)
}
