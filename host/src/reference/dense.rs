//! [`DenseLu`]: dense LU factors of `I - R F` with partial pivoting (faer), one per distinct reflectance
//! channel, reused for any number of right-hand sides.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::perm::PermRef;
use faer::{Mat, Par};

use super::error::{check_finite, check_len, ReferenceError};
use super::system::{RadiositySystem, Solution};
use crate::rgb::Rgb;

/// Largest system [`DenseLu::factor`] accepts: 4096 patches, `4096^2 * 8` bytes = 128 MiB per channel.
pub const MAX_DENSE_PATCHES: usize = 4096;

/// LU factors of one channel's matrix `I - R_c F`: `L` and `U` packed in one matrix, and the row permutation.
#[derive(Clone, Debug)]
struct ChannelLu {
    lu: Mat<f64>,
    perm_fwd: Vec<usize>,
    perm_bwd: Vec<usize>,
}

/// Dense LU factors of `I - R F`, one per distinct reflectance channel, reusable for any number of right-hand
/// sides.
///
/// Memory: `n^2 * 8` bytes per distinct channel (channels with identical reflectance share one factorization).
/// Factoring is `2/3 n^3` flops per distinct channel, each solve `2 n^2` per channel. Runs sequentially
/// (`Par::Seq`) so results are bit-for-bit reproducible.
#[derive(Clone, Debug)]
pub struct DenseLu<'a> {
    system: RadiositySystem<'a>,
    factors: Vec<ChannelLu>,
    /// Which entry of `factors` serves each channel.
    channel_factor: [usize; 3],
}

impl<'a> DenseLu<'a> {
    /// Factors `system` with the default limit [`MAX_DENSE_PATCHES`].
    ///
    /// # Errors
    /// See [`DenseLu::factor_with_limit`].
    pub fn factor(system: RadiositySystem<'a>) -> Result<Self, ReferenceError> {
        Self::factor_with_limit(system, MAX_DENSE_PATCHES)
    }

    /// Factors `system`, refusing more than `limit` patches (`limit^2 * 8` bytes per distinct channel).
    ///
    /// # Errors
    /// [`ReferenceError::TooLargeForDense`] above the limit; [`ReferenceError::SingularPivot`] if a pivot is zero
    /// or not finite (impossible for a validated system, but checked rather than assumed).
    pub fn factor_with_limit(system: RadiositySystem<'a>, limit: usize) -> Result<Self, ReferenceError> {
        let n = system.len();
        if n > limit {
            let bytes = (n as u128) * (n as u128) * 8;
            return Err(ReferenceError::TooLargeForDense { n, limit, bytes });
        }
        let mut factors: Vec<ChannelLu> = Vec::new();
        let mut channel_factor = [0usize; 3];
        for channel in 0..3 {
            // A grey scene (identical reflectance per channel) needs one factorization, not three.
            if let Some(same) = (0..channel).find(|&c| system.rho().iter().all(|r| r[c] == r[channel])) {
                channel_factor[channel] = channel_factor[same];
                continue;
            }
            channel_factor[channel] = factors.len();
            factors.push(Self::factor_channel(&system, channel)?);
        }
        Ok(Self { system, factors, channel_factor })
    }

    /// Builds and factors `I - R_c F` for one channel.
    fn factor_channel(system: &RadiositySystem<'_>, channel: usize) -> Result<ChannelLu, ReferenceError> {
        let n = system.len();
        let mut lu = Mat::<f64>::identity(n, n);
        for i in 0..n {
            let rho = system.rho()[i][channel];
            for (j, f) in system.form_factors().row(i) {
                lu[(i, j)] -= rho * f;
            }
        }
        let mut perm_fwd = vec![0usize; n];
        let mut perm_bwd = vec![0usize; n];
        let par = Par::Seq;
        let mut buffer =
            MemBuffer::new(factor::lu_in_place_scratch::<usize, f64>(n, n, par, Default::default()));
        factor::lu_in_place(
            lu.as_mut(),
            &mut perm_fwd,
            &mut perm_bwd,
            par,
            MemStack::new(&mut buffer),
            Default::default(),
        );
        for index in 0..n {
            let pivot = lu[(index, index)];
            if pivot == 0.0 || !pivot.is_finite() {
                return Err(ReferenceError::SingularPivot { channel, index });
            }
        }
        Ok(ChannelLu { lu, perm_fwd, perm_bwd })
    }

    /// The system this factorization solves.
    #[must_use]
    pub fn system(&self) -> RadiositySystem<'a> {
        self.system
    }

    /// Number of distinct factorizations held (1 for a grey scene, at most 3).
    #[must_use]
    pub fn factorization_count(&self) -> usize {
        self.factors.len()
    }

    /// Solves for one emission vector.
    ///
    /// # Errors
    /// A length mismatch or a non-finite emission.
    pub fn solve(&self, e: &[Rgb]) -> Result<Solution, ReferenceError> {
        let mut all = self.solve_many(&[e])?;
        Ok(all.remove(0))
    }

    /// Solves for several emission vectors with the same factorization.
    ///
    /// # Errors
    /// A length mismatch or a non-finite emission in any of them.
    pub fn solve_many(&self, rhs: &[&[Rgb]]) -> Result<Vec<Solution>, ReferenceError> {
        let n = self.system.len();
        for e in rhs {
            check_len("emission", e, n)?;
            check_finite("emission", e)?;
        }
        let k = rhs.len();
        let mut out: Vec<Vec<Rgb>> = vec![vec![Rgb::ZERO; n]; k];
        let par = Par::Seq;
        let mut buffer = MemBuffer::new(solve::solve_in_place_scratch::<usize, f64>(n, k, par));
        for channel in 0..3 {
            let f = &self.factors[self.channel_factor[channel]];
            let mut x = Mat::<f64>::from_fn(n, k, |i, col| rhs[col][i][channel]);
            let perm = PermRef::new_checked(&f.perm_fwd, &f.perm_bwd, n);
            // `L` (unit lower, diagonal implied) and `U` (upper) are packed in one matrix; faer's triangular
            // solves read only their own triangle.
            solve::solve_in_place(
                f.lu.as_ref(),
                f.lu.as_ref(),
                perm,
                x.as_mut(),
                par,
                MemStack::new(&mut buffer),
            );
            for (col, b) in out.iter_mut().enumerate() {
                for (i, bi) in b.iter_mut().enumerate() {
                    bi[channel] = x[(i, col)];
                }
            }
        }
        out.into_iter()
            .zip(rhs)
            .map(|(b, e)| {
                let residual = self.system.relative_residual(&b, e)?;
                Ok(Solution { b, residual, sweeps: 0 })
            })
            .collect()
    }
}
