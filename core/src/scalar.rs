//! Arithmetic for the solver: one trait, [`Scalar`], with an `f32` implementation for FPU devices and a
//! fixed-point one, [`Fixed`] (Q32.32 in an `i64`, integer only), for FPU-less devices.
//!
//! Every operation the solver uses is here, so both paths run the same solver code and the same tests.
//! Fixed-point operations saturate instead of wrapping: range `[-2^31, 2^31)` (about +-2.1e9) with resolution
//! `2^-32` (2.3e-10). Power values (`B * A`, see the crate docs) must stay inside that range; a saturated
//! value makes the solver report [`crate::solver::NoProgressReason::NotFinite`] (the hierarchical solver's
//! link loops report it at half that range instead, [`crate::hier`], "Range"). Precision is absolute, so
//! choose units (area unit, emission scale) that keep typical powers well above the resolution: each entry
//! applied rounds once per product to the nearest unit (at most 1 unit per receipt in all).
//!
//! Because rounding to nearest can round a transfer up, fixed-point shooting is guaranteed to converge for
//! tolerances `>= 6 * L * 2^-32 / (1 - rho_max)` power units, `L` the longest row: above that every shot
//! removes at least `tolerance * (1 - rho_max) - 3 L` units of unshot magnitude, at least `3 L` units.

use crate::codec::transfer::decode_transfer_dyadic;
use crate::codec::{decode_reflectance, pow2_f32, F32RowDecoder, Frac, RowDecoder};

/// The solver's per-entry internals of a [`Scalar`]. Public in a private module, so no other crate can name it,
/// implement [`Scalar`] or call these.
pub(crate) mod sealed {
    /// Reflectance cache and selection rank (see each item).
    pub trait Internal: Sized {
        /// A reflectance code decoded for the per-entry product (`mul_rho`): what the solver keeps per
        /// material so that an entry does not decode it again.
        type Rho: Copy + Default + core::fmt::Debug;
        /// Decodes reflectance code `code` (`code / 65536`, see [`crate::codec::decode_reflectance`]).
        #[must_use]
        fn rho(code: u16) -> Self::Rho;
        /// `self * rho`, bit for bit `self.mul_frac(decode_reflectance(code))` for the code `rho` was decoded from.
        #[must_use]
        fn mul_rho(self, rho: Self::Rho) -> Self;
        /// Selection rank, an integer ordered like the shooter choice: for a magnitude `self` (`>= 0`, or not
        /// usable) of slot `slot`, a larger rank means a larger magnitude, every unusable magnitude ranks above every
        /// usable one, and equal magnitudes rank the lower slot higher. One integer comparison per candidate, so a
        /// running maximum is a single compare-and-select (no chain of float compares and tie-breaks).
        type Rank: Copy + Ord + core::fmt::Debug;
        /// The rank of magnitude `self` held by `slot` (see `Rank`).
        #[must_use]
        fn rank(self, slot: u32) -> Self::Rank;
        /// A light group's intensity (one channel) prepared for the transfer relight's products with response
        /// codes under scale exponent `k` ([`crate::transfer`]).
        type TransferScale: Copy + core::fmt::Debug;
        /// Prepares `intensity` for codes under scale exponent `k`.
        #[must_use]
        fn transfer_scale(intensity: Self, k: i8) -> Self::TransferScale;
        /// `intensity * T`, `T` the response code `code` decoded under the scale's exponent: bit for bit
        /// `intensity.mul(from_dyadic(decode_transfer_dyadic(code, k)))`.
        #[must_use]
        fn transfer_term(code: u16, scale: Self::TransferScale) -> Self;
        /// Whether [`Internal::transfer_term_fast`] gives `transfer_term`'s bits for this scale.
        #[must_use]
        fn transfer_fast(scale: &Self::TransferScale) -> bool;
        /// `transfer_term` without the per-term choice of path, for scales where [`Internal::transfer_fast`]
        /// holds (for others any value).
        #[must_use]
        fn transfer_term_fast(code: u16, scale: Self::TransferScale) -> Self;
        /// A run's form-factor decoder prepared for hierarchical shooting's per-link products.
        type LinkDecoder: Copy + core::fmt::Debug;
        /// Prepares `row` (one run's decoder) for [`Internal::link_factor`] and [`Internal::link_product`].
        #[must_use]
        fn link_decoder(row: crate::codec::RowDecoder) -> Self::LinkDecoder;
        /// A form-factor code decoded for [`Internal::link_product`] (once per link, for its three channels).
        type LinkFactor: Copy + core::fmt::Debug;
        /// Decodes form-factor code `code` under `d`.
        #[must_use]
        fn link_factor(code: u32, d: Self::LinkDecoder) -> Self::LinkFactor;
        /// `self` times the factor `f`: bit for bit `self.mul_frac(row.decode(code))`, `row` the decoder `d` was
        /// prepared from and `f = link_factor(code, d)`.
        #[must_use]
        fn link_product(self, f: Self::LinkFactor) -> Self;
        /// [`Internal::link_factor`] for decoders where [`Internal::link_fast`] holds, without its checks.
        #[must_use]
        fn link_factor_fast(code: u32, d: Self::LinkDecoder) -> Self::LinkFactor;
        /// [`Internal::link_product`] for the factors of [`Internal::link_factor_fast`] and powers where
        /// [`Internal::link_fast`] holds, without its checks (for others any value).
        #[must_use]
        fn link_product_fast(self, f: Self::LinkFactor) -> Self;
        /// Whether the fast forms ([`Internal::link_factor_fast`], [`Internal::link_product_fast`]) give the
        /// checked ones' bits for `d`, every channel of `power` and every code read at the codec's width.
        #[must_use]
        fn link_fast(d: &Self::LinkDecoder, power: &[Self; 3]) -> bool;
        /// For `d` and `power` where [`Internal::link_fast`] holds (the caller's check, not repeated): whether
        /// every fast product of a channel of `power` with a code of `d` is small enough for [`Internal::mul_rho_small`] to
        /// give `mul_rho`'s bits.
        #[must_use]
        fn link_products_small(d: &Self::LinkDecoder, power: &[Self; 3]) -> bool;
        /// `mul_rho` without its check, for the products of runs where [`Internal::link_products_small`] holds
        /// (for others any value).
        #[must_use]
        fn mul_rho_small(self, rho: Self::Rho) -> Self;
        /// `self + other` for sums whose addend is below `2^62` raw in magnitude (fixed point; the products of
        /// hierarchical shooting's fast path): fixed point wraps instead of saturating and sets bit 31 of
        /// `flag` when the sum lies outside `[-2^62, 2^62)` raw, which is also where a wrapped sum lands, so a
        /// run of sums checks one flag at its end instead of saturating each ([`OUT_OF_RANGE`]). f32 adds (an
        /// overflow is infinite, which the solver's magnitudes find).
        #[must_use]
        fn add_flagged(self, other: Self, flag: &mut u32) -> Self;
    }
}

/// The bit of [`sealed::Internal::add_flagged`]'s flag that says a sum left its range.
pub(crate) const OUT_OF_RANGE: u32 = 1 << 31;

/// Numbers the solver computes with: `f32` and [`Fixed`], and only these (the trait is sealed: the solver's
/// per-entry internals, the reflectance cache and the selection rank, live in a crate-private supertrait).
pub trait Scalar: Copy + PartialEq + PartialOrd + core::fmt::Debug + sealed::Internal {
    /// Zero.
    const ZERO: Self;
    /// Sum (saturating for fixed point).
    #[must_use]
    fn add(self, other: Self) -> Self;
    /// Difference (saturating for fixed point).
    #[must_use]
    fn sub(self, other: Self) -> Self;
    /// Product (saturating for fixed point).
    #[must_use]
    fn mul(self, other: Self) -> Self;
    /// Quotient; division by zero gives zero.
    #[must_use]
    fn div(self, other: Self) -> Self;
    /// Product with a dyadic fraction (form factor, reflectance); fixed point rounds to nearest (half up).
    #[must_use]
    fn mul_frac(self, f: Frac) -> Self;
    /// Absolute value (saturating for fixed point).
    #[must_use]
    fn abs(self) -> Self;
    /// `mantissa * 2^exponent` (used to decode emission codes without floating point).
    #[must_use]
    fn from_dyadic(mantissa: u32, exponent: i32) -> Self;
    /// Conversion from f32 (fixed point decodes the bits with integer operations and saturates; NaN gives 0).
    #[must_use]
    fn from_f32(v: f32) -> Self;
    /// Conversion to f32 (for display and tests).
    #[must_use]
    fn to_f32(self) -> f32;
    /// Whether the value is usable: finite for f32, not saturated for fixed point.
    #[must_use]
    fn is_usable(self) -> bool;
    /// The smallest solver tolerance that is guaranteed to be reachable, given `units` = `6 L / (1 - rho_max)`
    /// rounded up (module docs): `units` resolution steps for fixed point; zero for `f32`, whose rounding is
    /// relative and does not leave an absolute floor of unshot power.
    #[must_use]
    fn convergence_floor(units: u64) -> Self;
}

impl Scalar for f32 {
    const ZERO: f32 = 0.0;
    fn add(self, other: f32) -> f32 {
        self + other
    }
    fn sub(self, other: f32) -> f32 {
        self - other
    }
    fn mul(self, other: f32) -> f32 {
        self * other
    }
    fn div(self, other: f32) -> f32 {
        if other == 0.0 {
            0.0
        } else {
            self / other
        }
    }
    fn mul_frac(self, f: Frac) -> f32 {
        self * f.to_f32()
    }
    fn abs(self) -> f32 {
        libm::fabsf(self)
    }
    fn from_dyadic(mantissa: u32, exponent: i32) -> f32 {
        mantissa as f32 * pow2_f32(exponent)
    }
    fn from_f32(v: f32) -> f32 {
        v
    }
    fn to_f32(self) -> f32 {
        self
    }
    fn is_usable(self) -> bool {
        self.is_finite()
    }
    fn convergence_floor(_units: u64) -> f32 {
        0.0
    }
}

impl sealed::Internal for f32 {
    /// `code * 2^-16` is exact in f32 (16 significant bits), and `mul_frac` multiplies by that same value.
    type Rho = f32;
    fn rho(code: u16) -> f32 {
        decode_reflectance(code).to_f32()
    }
    fn mul_rho(self, rho: f32) -> f32 {
        self * rho
    }
    /// The bits of a non-negative f32 order like its value, and infinity and NaN (sign cleared) lie above
    /// every finite value: bits above, the slot's complement below.
    type Rank = u64;
    fn rank(self, slot: u32) -> u64 {
        (u64::from(self.to_bits() & 0x7fff_ffff) << 32) | u64::from(!slot)
    }
    /// The response code's bits shifted into an f32's exponent and mantissa fields read as that f32 are the
    /// code's value times `2^-TRANSFER_RAW_SHIFT` exactly (its subnormal codes land on f32 subnormals with the
    /// same step), so a product with `intensity 2^(k + TRANSFER_RAW_SHIFT)` (exact when that is a normal f32)
    /// is the product with the decoded response, rounded once: one shift, one move and one multiply per
    /// channel. Intensities whose scaled value is not a normal f32 (huge or tiny) take the decode.
    ///
    /// The scaling itself is integer work on the bits (it runs per group and channel at every call of a chunked
    /// relight): a zero keeps its bits (`0 * 2^s` is that zero), a normal intensity whose exponent field stays
    /// in `1..=254` after adding `s` gets exactly `intensity 2^s`; everything else (subnormal, infinite, NaN, or
    /// a result out of the normal range) takes the decode path.
    type TransferScale = F32TransferScale;
    fn transfer_scale(intensity: f32, k: i8) -> F32TransferScale {
        let s = i32::from(k) + TRANSFER_RAW_SHIFT;
        let bits = intensity.to_bits();
        let exponent = ((bits >> 23) & 0xff) as i32;
        let (scaled, fast) = if bits & 0x7fff_ffff == 0 {
            (intensity, true)
        } else if (1..=254).contains(&exponent) && (1..=254).contains(&(exponent + s)) {
            // The exponent field grows by `s` with no carry into the sign: exactly `intensity 2^s`.
            (f32::from_bits(bits.wrapping_add((s as u32) << 23)), true)
        } else {
            (0.0, false)
        };
        F32TransferScale { scaled, fast, intensity, k }
    }
    #[inline(always)]
    fn transfer_term(code: u16, scale: F32TransferScale) -> f32 {
        if scale.fast {
            f32::transfer_term_fast(code, scale)
        } else {
            let (m, e) = decode_transfer_dyadic(code, scale.k);
            scale.intensity * f32::from_dyadic(m, e)
        }
    }
    fn transfer_fast(scale: &F32TransferScale) -> bool {
        scale.fast
    }
    #[inline(always)]
    fn transfer_term_fast(code: u16, scale: F32TransferScale) -> f32 {
        f32::from_bits(u32::from(code) << 11) * scale.scaled
    }
    /// `mul_frac` multiplies by `Frac::to_f32` of the decoded factor, which [`F32RowDecoder`] computes from the
    /// code's bits: the factor once per link, then one multiply per channel.
    type LinkDecoder = F32RowDecoder;
    fn link_decoder(row: RowDecoder) -> F32RowDecoder {
        F32RowDecoder::new(row)
    }
    type LinkFactor = f32;
    #[inline(always)]
    fn link_factor(code: u32, d: F32RowDecoder) -> f32 {
        d.decode(code)
    }
    #[inline(always)]
    fn link_product(self, f: f32) -> f32 {
        self * f
    }
    fn link_fast(d: &F32RowDecoder, _: &[f32; 3]) -> bool {
        d.is_fast()
    }
    #[inline(always)]
    fn link_factor_fast(code: u32, d: F32RowDecoder) -> f32 {
        d.decode_fast(code)
    }
    #[inline(always)]
    fn link_product_fast(self, f: f32) -> f32 {
        self * f
    }
    /// f32's reflectance product has no check to skip: never, so the one loop stays.
    fn link_products_small(_: &F32RowDecoder, _: &[f32; 3]) -> bool {
        false
    }
    #[inline(always)]
    fn mul_rho_small(self, rho: f32) -> f32 {
        self.mul_rho(rho)
    }
    #[inline(always)]
    fn add_flagged(self, other: f32, _: &mut u32) -> f32 {
        self + other
    }
}

/// An f32 intensity prepared for the transfer relight's products (`transfer_scale`).
#[derive(Clone, Copy, Debug)]
pub struct F32TransferScale {
    /// `intensity 2^(k + TRANSFER_RAW_SHIFT)`: exact when `fast`.
    scaled: f32,
    /// Whether `scaled` is exact and a normal f32 or zero (with the intensity), so the one-multiply product
    /// is the product with the decoded response.
    fast: bool,
    /// The intensity, for the decode path.
    intensity: f32,
    /// The group's scale exponent, for the decode path.
    k: i8,
}

/// `log2` of the factor between a FLOAT16 transfer code's value (row exponent 0: subnormal step `2^-26`) and the
/// f32 its bits make when shifted left by 11 (subnormal step `2^-138`).
const TRANSFER_RAW_SHIFT: i32 = 112;

/// Q32.32 fixed point in an `i64`: value = `raw / 2^32`. Saturating, integer only.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Fixed(pub i64);

/// Fractional bits of [`Fixed`].
pub const FIXED_FRAC_BITS: u32 = 32;

impl Fixed {
    /// Largest value.
    pub const MAX: Fixed = Fixed(i64::MAX);
    /// Smallest value.
    pub const MIN: Fixed = Fixed(i64::MIN);

    fn saturate(v: i128) -> Fixed {
        Fixed(v.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64)
    }
}

/// `v * 2^shift` for `shift` in any range, saturating to i64 (integer only).
fn shift_saturating(v: i128, shift: i32) -> Fixed {
    if shift >= 0 {
        if shift >= 64 || v.unsigned_abs() > (i64::MAX as u128) >> shift {
            return if v > 0 {
                Fixed::MAX
            } else if v < 0 {
                Fixed::MIN
            } else {
                Fixed(0)
            };
        }
        Fixed::saturate(v << shift)
    } else {
        Fixed::saturate(if -shift >= 127 {
            if v < 0 {
                -1
            } else {
                0
            }
        } else {
            v >> (-shift)
        })
    }
}

/// `(x m + 2^(s - 1)) >> s` in 64-bit integers: `mul_frac`'s one-product path, exact (the 128-bit path's bits)
/// when `|x m| < 2^62` and `s` is in `1..=62`; other operands get some value (wrapping, never a panic).
#[inline(always)]
fn round_shift_product(x: i64, m: i64, s: u32) -> i64 {
    x.wrapping_mul(m).wrapping_add(1i64.wrapping_shl(s.wrapping_sub(1))).wrapping_shr(s)
}

/// `(p + 2^(s - 1)) >> s` for `|p| < 2^62` and `s` in `1..=31`, in 32-bit halves: the half is added to the low
/// word (carry into the high word, which stays below `2^31` in magnitude), then the two words shift by `s`
/// without the choice a 64-bit shift by any amount makes. Other operands get some value (never a panic).
#[inline(always)]
fn round_shift_below_32(p: i64, s: u32) -> i64 {
    let (lo, carry) = (p as u32).overflowing_add(1u32.wrapping_shl(s.wrapping_sub(1)));
    let hi = ((p >> 32) as i32).wrapping_add(i32::from(carry));
    let low = lo.wrapping_shr(s) | (hi as u32).wrapping_shl(32u32.wrapping_sub(s));
    (i64::from(hi.wrapping_shr(s)) << 32) | i64::from(low)
}

/// `(p + 2^(s - 1)) >> s` for `|p| < 2^62` and `s` in `32..=62`: by `floor(floor(x / 2^32) / 2^t) = floor(x /
/// 2^(32 + t))`, the high word of `p + 2^(s - 1)` (below `2^31` in magnitude) shifted by `t = s - 32`, a 32-bit
/// shift. The half is `2^31` in the low word for `s = 32` (its carry, the low word's top bit before the
/// sum), else `2^(t - 1)` in the high word. Other operands get some value (never a panic).
#[inline(always)]
fn round_shift_from_32(p: i64, s: u32) -> i64 {
    let t = s.wrapping_sub(32);
    let hi = (p >> 32) as i32;
    let top = if t == 0 {
        hi.wrapping_add(((p as u32) >> 31) as i32)
    } else {
        hi.wrapping_add(1i32.wrapping_shl(t.wrapping_sub(1))).wrapping_shr(t)
    };
    i64::from(top)
}

/// `floor(n 2^32 / (m 2^s))` for a divisor of at most 24 significant bits (`m < 2^24`, `s < 64`), or `None`
/// when it is `2^63` or more: `Fixed::div`'s magnitude. Flooring by `2^s` first does not change the quotient
/// (`floor(floor(x / a) / b) = floor(x / (a b))` for positive integers), so the dividend is the up to 96-bit
/// `N = floor(n 2^(32 - s))`, divided by `m` as a long division in base `2^8`: its top word by one 32-bit
/// division, then one byte at a time, each partial dividend `(r << 8) | byte` below `2^32` because the
/// remainder `r` is below `m < 2^24`. Nine 32-bit divisions whatever the operands (one instruction each on a
/// Cortex-M3/M4), where a 64-bit or 128-bit division is a library loop whose length depends on them.
#[inline(always)]
fn div_short(n: u64, m: core::num::NonZeroU32, s: u32) -> Option<u64> {
    // N = top 2^64 + low.
    let (top, low) = if s >= FIXED_FRAC_BITS {
        (0u32, n >> (s - FIXED_FRAC_BITS))
    } else {
        ((n >> (FIXED_FRAC_BITS + s)) as u32, n << (FIXED_FRAC_BITS - s))
    };
    let mut r = top % m;
    let q_top = top / m;
    let mut halves = [0u32; 2];
    for (h, word) in halves.iter_mut().zip([(low >> 32) as u32, low as u32]) {
        for byte in word.to_be_bytes() {
            let x = (r << 8) | u32::from(byte);
            *h = (*h << 8) | (x / m);
            r = x % m;
        }
    }
    let q = (u64::from(halves[0]) << 32) | u64::from(halves[1]);
    (q_top == 0 && q >> 63 == 0).then_some(q)
}

impl Fixed {
    /// [`Scalar::mul_frac`] through the 128-bit product (the operands its 32-bit path does not take): kept out
    /// of line, so the inlined products stay small.
    #[inline(never)]
    #[cold]
    fn mul_frac_wide(self, f: Frac) -> Fixed {
        // |self| < 2^63 and mantissa < 2^32: the product fits in i128. Round half up: flooring would bias
        // every transfer down by half a unit on average, which adds up over thousands of shots.
        let shift = f.shift.min(126);
        let p = i128::from(self.0) * i128::from(f.mantissa);
        let half = if shift == 0 { 0 } else { 1i128 << (shift - 1) };
        shift_saturating(p + half, -(shift as i32))
    }
}

impl Scalar for Fixed {
    const ZERO: Fixed = Fixed(0);
    fn add(self, other: Fixed) -> Fixed {
        Fixed(self.0.saturating_add(other.0))
    }
    fn sub(self, other: Fixed) -> Fixed {
        Fixed(self.0.saturating_sub(other.0))
    }
    fn mul(self, other: Fixed) -> Fixed {
        // The magnitudes' product (zero-extended 64-bit operands: four 32 x 32-bit products, where the signed
        // 128-bit product also multiplies the sign extensions), then the signed product's floor by 2^32: for a
        // negative product `-ceil(P / 2^32)`. Saturated as `(a b) >> 32` in 128 bits would be.
        let p = u128::from(self.0.unsigned_abs()) * u128::from(other.0.unsigned_abs());
        if (self.0 < 0) != (other.0 < 0) {
            // P < 2^126, so the sum does not overflow; -2^63 itself is i64::MIN, below it saturates there too.
            let q = (p + ((1 << FIXED_FRAC_BITS) - 1)) >> FIXED_FRAC_BITS;
            Fixed(if q >> 63 == 0 { -(q as i64) } else { i64::MIN })
        } else {
            let q = p >> FIXED_FRAC_BITS;
            Fixed(if q >> 63 == 0 { q as i64 } else { i64::MAX })
        }
    }
    fn div(self, other: Fixed) -> Fixed {
        if other.0 == 0 {
            return Fixed(0);
        }
        // Divisors below 1.0 (`|other| < 2^32`), the usual areas, take two 64-bit divisions instead of a 128-bit
        // one: `|self| 2^32 / |other| = q 2^32 + (r 2^32) / |other|` with `q, r` the quotient and remainder of
        // `|self| / |other|`, and `r 2^32` fits since `r < |other| < 2^32`. Truncated toward zero and, when
        // `q < 2^31`, not saturated, as the 128-bit quotient below: the same bits.
        let (n, d) = (self.0.unsigned_abs(), other.0.unsigned_abs());
        // Divisors of at most 24 significant bits (every area, an f32 converted) take a long division by
        // 32-bit divisions, whose cost does not depend on the operands (`div_short`).
        let zeros = d.trailing_zeros();
        let m = d >> zeros;
        if let Some(m) = core::num::NonZeroU32::new(m as u32).filter(|_| m >> 24 == 0) {
            return match div_short(n, m, zeros) {
                Some(q) => Fixed(if (self.0 < 0) != (other.0 < 0) { -(q as i64) } else { q as i64 }),
                None if (self.0 < 0) != (other.0 < 0) => Fixed::MIN,
                None => Fixed::MAX,
            };
        }
        if d >> FIXED_FRAC_BITS == 0 {
            let (q, r) = (n / d, n % d);
            if q >> 31 == 0 {
                let m = ((q << FIXED_FRAC_BITS) | ((r << FIXED_FRAC_BITS) / d)) as i64;
                return Fixed(if (self.0 < 0) != (other.0 < 0) { -m } else { m });
            }
        }
        Fixed::saturate((i128::from(self.0) << FIXED_FRAC_BITS) / i128::from(other.0))
    }
    fn mul_frac(self, f: Frac) -> Fixed {
        // Mantissas below 2^31 with shifts `1..=95` (every form factor and reflectance) take 32 x 32-bit products
        // instead of a 128-bit one. With `self = hi 2^32 + lo` (`hi` signed and below 2^31 in magnitude, `lo <
        // 2^32`), the product is `P = P_hi 2^32 + P_lo` with `P_hi = hi m + floor(lo m / 2^32)` (below 2^63 in
        // magnitude) and `P_lo = lo m mod 2^32`. Adding `half = 2^(s - 1)` and flooring by `2^s`:
        // - `s > 32` (`t = s - 32`): `half = 2^(t - 1) 2^32` and `P_lo < 2^32` cannot carry into the quotient,
        //   so the result is `floor((P_hi + 2^(t - 1)) / 2^t)`, an arithmetic shift, and never saturates;
        // - `s <= 32`: `P_hi 2^32` is a multiple of `2^s`, so the result is `P_hi 2^(32 - s) + floor((P_lo +
        //   half) / 2^s)`, taken when neither the shift nor the sum overflows (the 128-bit path saturates).
        // Both are the bits of the 128-bit path below.
        //
        // Smaller operands, the usual ones, take one 64-bit product: with `|self| < 2^49` and `m < 2^13` (a
        // FLOAT16 form factor's mantissa) or `|self| < 2^46` and `m < 2^16` (a reflectance), `P = self m` is
        // below 2^62 in magnitude, so for shifts `1..=62` (`half <= 2^61`) `P + half` fits in an i64: the result
        // is its arithmetic shift, which cannot saturate, the bits of the 128-bit path.
        let a = self.0.unsigned_abs();
        if ((a >> 49 == 0 && f.mantissa >> 13 == 0) || (a >> 46 == 0 && f.mantissa >> 16 == 0))
            && (1..=62).contains(&f.shift)
        {
            return Fixed(round_shift_product(self.0, i64::from(f.mantissa), f.shift));
        }
        if f.mantissa >> 31 == 0 && (1..=95).contains(&f.shift) {
            let (s, m) = (f.shift, f.mantissa);
            let lo_m = u64::from(self.0 as u32) * u64::from(m);
            let p_hi = (self.0 >> 32) * i64::from(m) + (lo_m >> 32) as i64;
            if s > 32 {
                let t = s - 32;
                return Fixed((p_hi + (1i64 << (t - 1))) >> t);
            }
            let p_lo = lo_m & 0xffff_ffff;
            let low = ((p_lo + (1u64 << (s - 1))) >> s) as i64;
            let k = 32 - s;
            let high = p_hi << k;
            if high >> k == p_hi {
                if let Some(v) = high.checked_add(low) {
                    return Fixed(v);
                }
            }
        }
        self.mul_frac_wide(f)
    }
    fn abs(self) -> Fixed {
        Fixed(self.0.saturating_abs())
    }
    fn from_dyadic(mantissa: u32, exponent: i32) -> Fixed {
        shift_saturating(i128::from(mantissa), exponent.saturating_add(FIXED_FRAC_BITS as i32))
    }
    fn from_f32(v: f32) -> Fixed {
        let bits = v.to_bits();
        let exp = ((bits >> 23) & 0xff) as i32;
        if exp == 0xff {
            // Infinity saturates; NaN gives 0.
            return if bits & 0x7f_ffff != 0 {
                Fixed(0)
            } else if bits >> 31 != 0 {
                Fixed::MIN
            } else {
                Fixed::MAX
            };
        }
        let frac = i128::from(bits & 0x7f_ffff);
        let (m, e) = if exp == 0 { (frac, -149) } else { (frac | 0x80_0000, exp - 150) };
        let m = if bits >> 31 != 0 { -m } else { m };
        shift_saturating(m, e + FIXED_FRAC_BITS as i32)
    }
    fn to_f32(self) -> f32 {
        self.0 as f32 * pow2_f32(-(FIXED_FRAC_BITS as i32))
    }
    fn is_usable(self) -> bool {
        self.0 != i64::MAX && self.0 != i64::MIN
    }
    fn convergence_floor(units: u64) -> Fixed {
        Fixed(i64::try_from(units).unwrap_or(i64::MAX))
    }
}

impl sealed::Internal for Fixed {
    /// Fixed point rounds the product of the raw code (`mul_frac`): nothing to gain from decoding ahead, so the
    /// code itself is kept.
    type Rho = u16;
    fn rho(code: u16) -> u16 {
        code
    }
    /// `mul_frac`'s one 64-bit product path is taken for every `|self| < 2^46` (a reflectance's mantissa is
    /// below 2^16 and its shift 16): tested here on the magnitude alone, the shift a constant.
    #[inline(always)]
    fn mul_rho(self, rho: u16) -> Fixed {
        if self.0.unsigned_abs() >> 46 == 0 {
            return self.mul_rho_small(rho);
        }
        self.mul_frac(decode_reflectance(rho))
    }
    /// A magnitude is a saturating sum of saturating absolute values: in `0..=i64::MAX`, the unusable one
    /// `i64::MAX` (a negative value, which a magnitude never is, ranks as its absolute value).
    type Rank = u128;
    fn rank(self, slot: u32) -> u128 {
        (u128::from(self.0.unsigned_abs().min(i64::MAX as u64)) << 32) | u128::from(!slot)
    }
    /// Fixed point decodes the response exactly and rounds the one product.
    type TransferScale = (Fixed, i8);
    fn transfer_scale(intensity: Fixed, k: i8) -> (Fixed, i8) {
        (intensity, k)
    }
    fn transfer_term(code: u16, scale: (Fixed, i8)) -> Fixed {
        if Fixed::transfer_fast(&scale) {
            return Fixed::transfer_term_fast(code, scale);
        }
        let (m, e) = decode_transfer_dyadic(code, scale.1);
        scale.0.mul(Fixed::from_dyadic(m, e))
    }
    /// Intensities below `2^18` in magnitude (raw below `2^50`) under scale exponents `K <= 12`: every code's
    /// `m 2^e` then has `m < 2^13` and `e = K - s <= 0` (a FLOAT16 code's shift `s` is at least 12), where
    /// [`Internal::transfer_term_fast`] is exact.
    fn transfer_fast(scale: &(Fixed, i8)) -> bool {
        scale.0 .0.unsigned_abs() >> 50 == 0 && scale.1 <= 12
    }
    /// `intensity.mul(Fixed::from_dyadic(m, e))` for the code's `m 2^e` in 64-bit integers, for scales where
    /// [`Internal::transfer_fast`] holds (`|I| < 2^50` raw, `m < 2^13`, `e <= 0`). There `from_dyadic` is
    /// `R = floor(m 2^(e + 32))` (exact while `e >= -32`, else `m >> (-e - 32)`), below `2^45`, and `mul` is
    /// `floor(I R / 2^32)` with `|I R| < 2^63`:
    /// - `e >= -32`: `I R / 2^32 = I m 2^e` exactly, so the result is `floor(I m / 2^-e)`, an arithmetic shift of
    ///   the 64-bit `I m`;
    /// - `e < -32`: `R = m >> (-e - 32) < 2^13` (zero from `-e - 32 >= 13`), and the result is `(I R) >> 32`.
    ///
    /// Neither saturates (`|I m| < 2^63`), so both are the bits of the 128-bit path. Other scales get some value
    /// (wrapping, never a panic).
    #[inline(always)]
    fn transfer_term_fast(code: u16, scale: (Fixed, i8)) -> Fixed {
        let (m, e) = decode_transfer_dyadic(code, scale.1);
        let (i, m, s) = (scale.0 .0, i64::from(m), e.wrapping_neg() as u32);
        Fixed(if s <= 32 {
            i.wrapping_mul(m) >> s
        } else if s < 45 {
            i.wrapping_mul(m >> (s - 32)) >> FIXED_FRAC_BITS
        } else {
            // R = 0 (or e > 0, outside the path).
            0
        })
    }
    /// Fixed point rounds each product of the dyadic factor (`mul_frac`): the row's decoder as it is.
    type LinkDecoder = RowDecoder;
    fn link_decoder(row: RowDecoder) -> RowDecoder {
        row
    }
    type LinkFactor = Frac;
    #[inline(always)]
    fn link_factor(code: u32, d: RowDecoder) -> Frac {
        d.decode(code)
    }
    #[inline(always)]
    fn link_product(self, f: Frac) -> Fixed {
        self.mul_frac(f)
    }
    /// Rows whose values have mantissas below `2^13` and shifts in `1..=62` (FLOAT16 rows of exponents in
    /// the usual range) shot with powers below `2^49` raw in magnitude: every product then takes `mul_frac`'s
    /// one 64-bit product path, which [`Internal::link_product_fast`] computes without `mul_frac`'s checks.
    fn link_fast(d: &RowDecoder, power: &[Fixed; 3]) -> bool {
        let (least, largest) = d.shift_range();
        d.mantissa_bits() <= 13
            && least >= 1
            && largest <= 62
            && power.iter().all(|p| p.0.unsigned_abs() >> 49 == 0)
    }
    /// Codes read at the codec's width need no clamp.
    #[inline(always)]
    fn link_factor_fast(code: u32, d: RowDecoder) -> Frac {
        d.decode_unclamped(code)
    }
    /// `mul_frac`'s one-product path, `(p m + 2^(s - 1)) >> s`, with the shift's two ranges taken apart
    /// ([`round_shift_below_32`], [`round_shift_from_32`]): a 64-bit shift by a variable amount costs a 32-bit
    /// core both of its halves' sequences and a choice between them.
    #[inline(always)]
    fn link_product_fast(self, f: Frac) -> Fixed {
        let p = self.0.wrapping_mul(i64::from(f.mantissa));
        Fixed(if f.shift < 32 { round_shift_below_32(p, f.shift) } else { round_shift_from_32(p, f.shift) })
    }
    /// With mantissas below `2^b` and shifts of at least `s` (the row's), a fast product `x = (p m + 2^(s'-1))
    /// >> s'` is below `|p| 2^(b - s) + 1` in magnitude, so `|p| < 2^(45 - b + s)` keeps every product below
    /// `2^46`, where `mul_rho` takes its 64-bit product path ([`Internal::mul_rho_small`]).
    fn link_products_small(d: &RowDecoder, power: &[Fixed; 3]) -> bool {
        let bound = (45 + d.shift_range().0).saturating_sub(d.mantissa_bits()).min(63);
        power.iter().all(|p| p.0.unsigned_abs() >> bound == 0)
    }
    /// `mul_frac`'s one 64-bit product for a reflectance (mantissa below 2^16, shift 16): `mul_rho`'s bits for
    /// `|self| < 2^46`.
    #[inline(always)]
    fn mul_rho_small(self, rho: u16) -> Fixed {
        Fixed(round_shift_product(self.0, i64::from(rho), 16))
    }
    /// The sum lies in `[-2^62, 2^62)` exactly when its two top bits are equal: bit 31 of `hi ^ (hi << 1)`,
    /// `hi` its top word. With `|self| < 2^63` and `|other| < 2^62`, a sum that wraps lands within `2^62` of
    /// the far end of the range, where those bits differ, so every wrapped sum is flagged, and so is every
    /// exact sum of `2^62` or more, which a saturating add would keep (the flagged range is half the type's).
    #[inline(always)]
    fn add_flagged(self, other: Fixed, flag: &mut u32) -> Fixed {
        let r = self.0.wrapping_add(other.0);
        let hi = (r >> 32) as u32;
        *flag |= hi ^ (hi << 1);
        Fixed(r)
    }
}

#[cfg(test)]
mod tests {
    use super::sealed::Internal;
    use super::*;

    #[test]
    fn fixed_link_products_fast_are_the_checked_products() {
        // Every code of the codecs at row exponents across the range, powers on both sides of 2^49: where
        // `link_fast` holds, the unchecked products are the checked ones' bits; the premise holds for FLOAT16 rows
        // of small exponents with moderate powers (the path is not dead).
        use crate::codec::FfCodec;
        let powers = [
            [Fixed(0), Fixed(1), Fixed(-1)],
            [Fixed(1 << 32), Fixed(-(5 << 31)), Fixed(0x1234_5678_9abc)],
            [Fixed((1 << 49) - 1), Fixed(-((1 << 49) - 1)), Fixed(3)],
            [Fixed(1 << 49), Fixed(7), Fixed(-7)],
        ];
        let (mut taken, mut small_taken) = (0, 0);
        for codec in [FfCodec::FLOAT16, FfCodec::FLOAT8, FfCodec::LINEAR16, FfCodec::LINEAR8] {
            for e in [0u8, 1, 5, 20, 40, 50, 63] {
                let d = codec.row_decoder(e);
                // The largest powers the small-products rule admits for this row (the bound's edge).
                let edge = (45 + d.shift_range().0).saturating_sub(d.mantissa_bits()).min(62);
                let top = (1i64 << edge) - 1;
                let edges =
                    [[Fixed(top), Fixed(-top), Fixed(top >> 1)], [Fixed(top + 1), Fixed(0), Fixed(0)]];
                for power in powers.iter().chain(&edges) {
                    if !Fixed::link_fast(&d, power) {
                        continue;
                    }
                    taken += 1;
                    let small = Fixed::link_products_small(&d, power);
                    small_taken += usize::from(small);
                    for code in 0..=u32::from(codec.max_code()) {
                        let (fast, checked) = (Fixed::link_factor_fast(code, d), Fixed::link_factor(code, d));
                        let (got, want) = (
                            power.map(|p| p.link_product_fast(fast)),
                            power.map(|p| p.link_product(checked)),
                        );
                        assert_eq!(got, want, "{codec} e {e} code {code} power {power:?}");
                        // Where the run's products are declared small, the unchecked reflectance product is
                        // `mul_rho`'s, for reflectances across the codes.
                        for rho in [1u16, 0x8000, 0xcccd, u16::MAX].into_iter().filter(|_| small) {
                            for x in got {
                                assert!(x.0.unsigned_abs() >> 46 == 0, "{codec} e {e} code {code} {x:?}");
                                assert_eq!(x.mul_rho_small(rho), x.mul_rho(rho));
                            }
                        }
                    }
                }
            }
        }
        assert!(taken >= 10, "the fast path's premise held for {taken} rows and powers");
        assert!(small_taken >= 5 && small_taken < taken, "small products held for {small_taken} of {taken}");
        assert!(Fixed::link_fast(&FfCodec::FLOAT16.row_decoder(0), &[Fixed(1 << 32); 3]));
    }

    #[test]
    fn fixed_flagged_sums_are_exact_or_flagged() {
        // Operands at and around the flag's edges (2^62) and the type's (2^63), addends below 2^62: a sum in
        // [-2^62, 2^62) is exact and unflagged, every other (wrapped or not) is flagged.
        let edge = 1i64 << 62;
        let values = [0, 1, -1, edge - 1, edge, -edge, -edge - 1, i64::MAX, i64::MIN, i64::MAX - 5, edge / 3];
        let addends = [0, 1, -1, edge - 1, -(edge - 1), 1 << 40, -(1 << 40), edge / 2];
        let mut flagged = 0;
        for a in values {
            for b in addends {
                let mut flag = 0u32;
                let got = Fixed(a).add_flagged(Fixed(b), &mut flag);
                let exact = i128::from(a) + i128::from(b);
                let inside = (-(1i128 << 62)..1i128 << 62).contains(&exact);
                assert_eq!(flag & OUT_OF_RANGE == 0, inside, "{a} + {b}");
                if inside {
                    assert_eq!(i128::from(got.0), exact, "{a} + {b}");
                }
                flagged += usize::from(!inside);
            }
        }
        assert!(flagged > 10, "{flagged}");
    }

    #[test]
    fn fixed_transfer_terms_match_the_128_bit_product() {
        // Every code's mantissa and exponent under scale exponents across the valid range, with intensities on
        // both sides of the 64-bit path's bound (raw 2^50), signed: the fast path's bits against the 128-bit one.
        let intensities = [
            0i64,
            1,
            -1,
            3,
            (1 << 32) - 1,
            1 << 32,
            -(1 << 32),
            5 << 31,
            0x1234_5678_9abc,
            -0x1234_5678_9abc,
            (1 << 50) - 1,
            -((1 << 50) - 1),
            1 << 50,
            -(1 << 50),
            i64::MAX,
            i64::MIN,
        ];
        for code in (0..=u16::MAX).step_by(7).chain([1, 0xfff, 0x1000, 0xffff]) {
            for k in [-96i8, -60, -45, -33, -32, -20, -13, -12, -7, -1, 0, 1, 13, 20, 32] {
                let (m, e) = decode_transfer_dyadic(code, k);
                if k <= 12 {
                    assert!(m >> 13 == 0 && e <= 0, "the fast path's premise: code {code:#x}, k {k}");
                }
                for &i in &intensities {
                    let want = Fixed(i).mul(Fixed::from_dyadic(m, e));
                    let got = Fixed::transfer_term(code, Fixed::transfer_scale(Fixed(i), k));
                    assert_eq!(got, want, "code {code:#x}, k {k}, intensity raw {i}");
                }
            }
        }
    }

    #[test]
    fn fixed_div_and_mul_match_the_128_bit_quotient_and_product() {
        // The division's paths (short divisors, divisors below 1.0) against the 128-bit quotient, and the product
        // against the signed 128-bit product, signs, edges and saturation included.
        let values = [
            0i64,
            1,
            -1,
            3,
            (1 << 32) - 1,
            1 << 32,
            -(1 << 32) + 7,
            (1 << 40) + 12345,
            -(1 << 45) - 3,
            (1 << 62) + 1,
            i64::MAX,
            i64::MIN,
            i64::MIN + 1,
        ];
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut more = [0i64; 64];
        for v in &mut more {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            *v = (seed as i64) >> (seed % 48);
        }
        // Divisors of at most 24 significant bits (the short long division): areas as the solver converts them,
        // the edges of its premise (2^24 - 1 and 2^24 at every shift), and random ones.
        let mut short: Vec<i64> = [1e-9f32, 3.7e-5, 0.01, 0.3, 1.0, 1.5, 2.0, 343.0, 1.3e4, 5.5e5, 2.1e8]
            .iter()
            .flat_map(|&a| [Fixed::from_f32(a).0, -Fixed::from_f32(a).0])
            .collect();
        for k in [0u32, 1, 8, 31, 32, 33, 38, 39] {
            short.extend([((1i64 << 24) - 1) << k, (1i64 << 24) << k, -(((1i64 << 24) - 3) << k)]);
        }
        for _ in 0..64 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            short.push(((seed & 0xff_ffff) as i64 | 1) << (seed >> 58));
        }
        assert!(short.iter().all(|&d| d != 0));
        assert!(short.iter().filter(|&&d| (d.unsigned_abs() >> d.trailing_zeros()) >> 24 == 0).count() > 100);
        for &a in values.iter().chain(&more) {
            for &b in values.iter().chain(&more).chain(&short) {
                let expected = if b == 0 {
                    Fixed(0)
                } else {
                    Fixed::saturate((i128::from(a) << FIXED_FRAC_BITS) / i128::from(b))
                };
                assert_eq!(Fixed(a).div(Fixed(b)), expected, "{a} / {b}");
                // The product from the magnitudes' product against the signed 128-bit one, on the same pairs.
                let product = Fixed::saturate((i128::from(a) * i128::from(b)) >> FIXED_FRAC_BITS);
                assert_eq!(Fixed(a).mul(Fixed(b)), product, "{a} * {b}");
            }
        }
    }

    #[test]
    fn fixed_mul_frac_matches_the_128_bit_product() {
        // The split paths (shifts 1..=95, mantissas below 2^31) against the 128-bit product, signs, edges and
        // saturation included, and the shifts and mantissas outside them.
        let reference = |x: i64, f: Frac| {
            let shift = f.shift.min(126);
            let p = i128::from(x) * i128::from(f.mantissa);
            let half = if shift == 0 { 0 } else { 1i128 << (shift - 1) };
            shift_saturating(p + half, -(shift as i32))
        };
        let mut xs =
            vec![0i64, 1, -1, 2, -2, (1 << 32) - 1, 1 << 32, -(1 << 32), i64::MAX, i64::MIN, i64::MIN + 1];
        // Both sides of the one-product path's bounds (2^46, 2^49) and beyond.
        for b in [46, 47, 49, 50] {
            xs.extend([(1i64 << b) - 1, 1 << b, -((1i64 << b) - 1), -(1i64 << b), (1 << b) + 1]);
        }
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..400 {
            let v = next();
            xs.push((v as i64) >> (v % 64));
        }
        let mut mantissas = vec![
            0u32,
            1,
            2,
            0xffff,
            0x1_0000,
            0x1_ffff,
            u32::MAX,
            u32::MAX - 1,
            1 << 31,
            (1 << 31) - 1,
            0x1fff,
            0x2000,
        ];
        for _ in 0..40 {
            let v = next();
            mantissas.push((v as u32) >> (v % 32));
        }
        for &x in &xs {
            for &mantissa in &mantissas {
                for shift in (0..=100).chain([120, 126, 127, 130]) {
                    let f = Frac { mantissa, shift };
                    assert_eq!(Fixed(x).mul_frac(f), reference(x, f), "{x} * {mantissa} / 2^{shift}");
                }
            }
        }
    }

    #[test]
    fn f32_transfer_terms_are_the_products_with_the_decoded_responses() {
        use crate::codec::transfer::{TRANSFER_MAX_EXPONENT, TRANSFER_MIN_EXPONENT};
        let intensities =
            [1.0f32, -0.3, 7.77e5, 1.3e-30, 1e-44, 3.0e38, 0.0, -0.0, 2.5e-3, f32::MIN_POSITIVE, -2.0e20];
        for k in [TRANSFER_MIN_EXPONENT, -40, -1, 0, 5, 15, 16, TRANSFER_MAX_EXPONENT] {
            for &i in &intensities {
                let scale = f32::transfer_scale(i, k);
                if scale.fast {
                    // The scaled intensity is exactly `i 2^(k + 112)`.
                    let exact = f64::from(i) * 2f64.powi(i32::from(k) + TRANSFER_RAW_SHIFT);
                    assert_eq!(f64::from(scale.scaled), exact, "k {k} intensity {i}");
                }
                for code in (0..=u16::MAX).step_by(37).chain([0, 1, 0x0fff, 0x1000, u16::MAX]) {
                    let (m, e) = decode_transfer_dyadic(code, k);
                    let want = i * f32::from_dyadic(m, e);
                    let got = f32::transfer_term(code, scale);
                    assert_eq!(got.to_bits(), want.to_bits(), "k {k} intensity {i} code {code:#x}");
                    if f32::transfer_fast(&scale) {
                        let fast = f32::transfer_term_fast(code, scale);
                        assert_eq!(
                            fast.to_bits(),
                            want.to_bits(),
                            "fast: k {k} intensity {i} code {code:#x}"
                        );
                    }
                }
            }
        }
        // The fast form is taken wherever the scaled intensity is a normal f32, and only there.
        assert!(f32::transfer_scale(1.0, 0).fast);
        // 2^(15 + 112) is the largest power of two below f32's top.
        assert!(f32::transfer_scale(1.0, 15).fast);
        assert!(!f32::transfer_scale(1.0, TRANSFER_MAX_EXPONENT).fast);
        assert!(!f32::transfer_scale(3.0e38, 0).fast);
        assert!(!f32::transfer_scale(1e-44, TRANSFER_MIN_EXPONENT).fast);
    }

    #[test]
    fn fixed_conversions_and_saturation() {
        assert_eq!(Fixed::from_f32(1.5), Fixed(3 << 31));
        assert_eq!(Fixed::from_f32(-0.25), Fixed(-(1 << 30)));
        assert_eq!(Fixed::from_f32(1e12), Fixed::MAX);
        assert_eq!(Fixed::from_f32(-1e12), Fixed::MIN);
        assert_eq!(Fixed::from_f32(f32::NAN), Fixed(0));
        assert_eq!(Fixed::from_dyadic(3, -1).to_f32(), 1.5);
        assert_eq!(Fixed::MAX.add(Fixed(1)), Fixed::MAX);
        assert_eq!(Fixed::MIN.abs(), Fixed::MAX);
        assert_eq!(Fixed::from_f32(3.0).mul(Fixed::from_f32(-0.5)).to_f32(), -1.5);
        assert_eq!(Fixed::from_f32(3.0).div(Fixed::from_f32(-0.5)).to_f32(), -6.0);
        assert_eq!(Fixed::from_f32(3.0).div(Fixed(0)), Fixed(0));
        assert_eq!(Fixed::from_f32(3.0).mul_frac(Frac { mantissa: 1, shift: 2 }).to_f32(), 0.75);
        assert_eq!(Fixed::MAX.mul(Fixed::MAX), Fixed::MAX);
    }

    /// The shooter choice the rank must reproduce: an unusable magnitude above every usable one; otherwise the
    /// larger magnitude, ties to the lower slot. (Between two unusable magnitudes the rank picks one
    /// deterministically; the solver reports either as not finite.)
    fn ranks_above<S: Scalar>(a: u32, ka: S, b: u32, kb: S) -> Option<bool> {
        match (ka.is_usable(), kb.is_usable()) {
            (false, false) => None,
            (false, true) => Some(true),
            (true, false) => Some(false),
            (true, true) => Some(ka > kb || (ka == kb && a < b)),
        }
    }

    fn check_ranks<S: Scalar>(keys: &[S]) {
        let slots = [0u32, 1, 7, u32::MAX - 1, u32::MAX];
        for &ka in keys {
            for &kb in keys {
                for &a in &slots {
                    for &b in &slots {
                        if a == b {
                            continue;
                        }
                        if let Some(want) = ranks_above(a, ka, b, kb) {
                            assert_eq!(ka.rank(a) > kb.rank(b), want, "{ka:?}@{a} vs {kb:?}@{b}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn rank_orders_like_the_shooter_choice() {
        let f =
            [0.0f32, 1e-45, 1e-38, 0.5, 1.0, 1.0 + f32::EPSILON, 3.0e38, f32::MAX, f32::INFINITY, f32::NAN];
        check_ranks(&f);
        // A magnitude is a sum of absolute values: NaN arising from it has its sign cleared by `abs`.
        assert!((-f32::NAN).abs().rank(0) > f32::MAX.rank(0));
        let x = [Fixed(0), Fixed(1), Fixed(2), Fixed(1 << 40), Fixed(i64::MAX - 1), Fixed::MAX];
        check_ranks(&x);
    }

    /// The decoded reflectance the solver caches multiplies exactly as the code it came from.
    #[test]
    fn mul_rho_is_mul_frac_of_the_code() {
        let xs = [0.0f32, 1e-30, 0.1, 1.0, 3.7, 1e6, -2.5, f32::MAX];
        for code in (0..=u16::MAX).step_by(7).chain([u16::MAX]) {
            let frac = decode_reflectance(code);
            for x in xs {
                assert_eq!(x.mul_rho(f32::rho(code)).to_bits(), x.mul_frac(frac).to_bits(), "{x} * {code}");
                let fx = Fixed::from_f32(x);
                assert_eq!(fx.mul_rho(Fixed::rho(code)), fx.mul_frac(frac), "{x} * {code} (fixed)");
            }
            // Both sides of the 64-bit path's bound, 2^46 raw.
            for raw in [(1i64 << 46) - 1, 1 << 46, -((1i64 << 46) - 1), -(1i64 << 46), i64::MIN, i64::MAX] {
                let fx = Fixed(raw);
                assert_eq!(fx.mul_rho(Fixed::rho(code)), fx.mul_frac(frac), "{raw} * {code} (fixed)");
            }
        }
    }
}
