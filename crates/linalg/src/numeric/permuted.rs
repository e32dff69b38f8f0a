//! The matrix a numeric factorisation reads ([`Permuted`]): a leaf that
//! the factorisation and its gather plan both name.

use crate::Real;

/// A symmetric matrix stored with both triangles in compressed columns
/// (the normal matrix `M` as assembled), and the fill-reducing permutation
/// (`fwd[new] = old`, `inv[old] = new`) the factor's columns follow.
#[derive(Clone, Copy)]
pub struct Permuted<'a> {
    /// Column pointers of `M` (both triangles).
    pub col_ptr: &'a [usize],
    /// Row indices of `M`, sorted within each column.
    pub row_idx: &'a [usize],
    /// `M`'s values, in the order of `row_idx`.
    pub values: &'a [Real],
    /// The fill-reducing permutation `(fwd, inv)`, if any.
    pub perm: Option<(&'a [usize], &'a [usize])>,
}
