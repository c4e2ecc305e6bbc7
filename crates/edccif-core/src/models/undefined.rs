//! What a model returns for a state dimension it does not define: NaN, which
//! every filter reports as a named non-finite error without committing anything.

use nalgebra::{RealField, SMatrix};

/// A matrix of NaN: what a model returns for a dimension it does not define.
#[inline]
pub(super) fn nan_matrix<T: RealField + Copy, const R: usize, const C: usize>() -> SMatrix<T, R, C>
{
    SMatrix::from_element(T::zero() / T::zero())
}

/// A vector of NaN (see [`nan_matrix`]).
#[inline]
pub(super) fn nan_vector<T: RealField + Copy, const R: usize>() -> SMatrix<T, R, 1> {
    nan_matrix()
}
