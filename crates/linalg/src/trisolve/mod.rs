//! Supernodal triangular solves `L Lᵀ x = b` for a few right-hand sides.
//!
//! A DEND iteration solves the factor cache's `M = L Lᵀ` for the three
//! coordinates at once (design.md §4.4). faer's general solve calls a packed
//! GEMM per supernode, which pays off for wide right-hand sides; with three
//! columns it spends its time packing the factor and in per-call overhead
//! (measured on tube:10000: 11.8 ms per solve for 2.65 M factor nonzeros,
//! ~3.6 GB/s). This module runs the same two sweeps (the supernodal layout
//! of Ng & Peyton 1993, as faer stores it) with the right-hand sides
//! interleaved four to a row (`[f64; 4]`, the fourth lane padding or a
//! fourth column), so every factor entry is read once per sweep and used in
//! one 4-lane multiply-add: the sweeps are bound by memory bandwidth, not by
//! call overhead.
//!
//! Both sweeps can run on two threads ([`parallel::SolvePlan`]): two
//! disjoint groups of subtrees of the supernodal elimination tree are
//! independent, only their common ancestors are solved by one thread.
//!
//! The kernels are compiled twice: for the baseline target and with
//! AVX2+FMA, chosen at run time.

mod dense;
mod kernels;
mod parallel;
pub mod simplicial;
mod sweep;
mod types;

pub use parallel::SolvePlan;
pub use types::{FactorValue, Supernodal};

use faer::dyn_stack::{MemStack, StackReq};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::MatMut;

use crate::Real;
use sweep::{backward, forward};
use types::{by_four_columns, Lanes, Rows, Scatter};

/// Scratch for [`solve_in_place`] (the permuted right-hand sides and the
/// gather/scatter buffers of one or two threads).
pub fn scratch(sym: &SymbolicSupernodalCholesky<usize>, plan: Option<&SolvePlan>) -> StackReq {
    let rows = scratch_rows(sym);
    StackReq::all_of(&[
        StackReq::new::<Lanes>(sym.nrows()),
        StackReq::new::<Lanes>(rows),
        plan.map_or(StackReq::EMPTY, |p| p.scratch(rows)),
    ])
}

/// `M X = B` for a supernodal factor, four columns of `b` at a time:
/// gathered into the factor's row order, solved (on two threads when a
/// `plan` is given), scattered back.
pub fn solve_in_place<V: FactorValue>(
    sn: &SymbolicSupernodalCholesky<usize>,
    perm: Option<faer::perm::PermRef<'_, usize>>,
    values: &[V],
    plan: Option<&SolvePlan>,
    b: MatMut<'_, Real>,
    stack: &mut MemStack,
) {
    let n = sn.nrows();
    assert_eq!(values.len(), sn.len_val());
    assert_eq!(b.nrows(), n);
    let factor = Supernodal { sym: sn, values };
    let rows = scratch_rows(sn);
    let (mut x, stack) = stack.make_with::<Lanes>(n, |_| [0.0; 4]);
    let (mut tmp, stack) = stack.make_with::<Lanes>(rows, |_| [0.0; 4]);
    by_four_columns(b, perm, &mut x, |x| match plan {
        Some(p) => p.solve(factor, x, &mut tmp, stack),
        None => {
            let shared = Rows::new(x);
            let all = 0..sn.n_supernodes();
            forward(factor, all.clone(), shared, &mut tmp, Scatter::Direct);
            backward(factor, all.rev(), shared, &mut tmp);
        }
    });
}

/// Length of the gather/scatter buffer of one thread: the longest
/// off-diagonal pattern of a supernode.
pub(crate) fn scratch_rows(sym: &SymbolicSupernodalCholesky<usize>) -> usize {
    let cpr = sym.col_ptr_for_row_idx();
    (0..sym.n_supernodes())
        .map(|s| cpr[s + 1] - cpr[s])
        .max()
        .unwrap_or(0)
}

pub use crate::cpu::has_fma;

#[cfg(test)]
mod tests;
