//! Helpers shared by the crate's tests.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltError;
use faer::sparse::linalg::cholesky::SymbolicCholesky;
use faer::sparse::SparseColMat;
use faer::{Par, Side};

/// faer's own numeric Cholesky factorisation of `m` (lower triangle) on
/// the symbolic analysis `sym`: the independent reference the kernels are
/// tested against. `Err` holds the failing pivot.
pub(crate) fn faer_values(
    sym: &SymbolicCholesky<usize>,
    m: &SparseColMat<usize, f64>,
) -> Result<Vec<f64>, usize> {
    let mut values = vec![0.0; sym.len_val()];
    let mut mem =
        MemBuffer::new(sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()));
    sym.factorize_numeric_llt::<f64>(
        &mut values,
        m.as_ref(),
        Side::Lower,
        Default::default(),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|e| match e {
        LltError::NonPositivePivot { index } => index,
    })?;
    Ok(values)
}
