//! The stacked rows of eq. (24), applied without storing them.
//!
//! On the free rows `R`, with `W = diag(√A_i)` (see [`super::system`]):
//!
//! ```text
//!   J = [ W R A     ]      r = b - J Y = [ W (t - A Y)_R        ]
//!       [ √λ2 W R L ]                    [ √λ2 W (δ̂ - L Y)_R   ]
//! ```
//!
//! Every energy's `A` (design.md §3) is a product of `L` with a factor made of
//! `I`, `L` and the diagonal `G`: `A = P L` with `P = c_I I + c_L L − 2 g G`
//! (membrane `P = I`, thin plate `P = L`, combined `k_s I + k_b L`, total
//! curvature `L − 2G`), or, for the paper's literal `L² − 2 L G`,
//! `A = L (L − 2G)`. So `J Y` and `J_Uᵀ r` take two products with `L`'s
//! rows (~7 entries) instead of one with the rows of `A` (~19 entries) and
//! `L` stored in `J` and `J_Uᵀ`: half the bytes read per iteration, and no
//! `J` kept per constraint set.
//!
//! For `A = P L` the internal target is `t = P(T δ)` (default mode) or
//! `A X = P δ`, so `t − A Y = P(base − L Y)` with `base = T δ` or `δ`: one
//! product with `L` on all rows and one on `R`. The gradient
//! `J_Uᵀ r = (Aᵀ u + Lᵀ v)_U` with `u = W r_A`, `v = √λ2 W r_L` (zero off
//! `R`): for `A = P L`, `Lᵀ (Pᵀ u + v)`; for `A = L (L − 2G)`,
//! `Lᵀ (Lᵀ u + v) − 2 G Lᵀ u`. `Lᵀ x = Lbar (D x)`, `D = diag(1/A_i)`.

use rayon::prelude::*;
use sprs::CsMat;

use super::energy::Shape;
use crate::mesh::{Point, Real};
use crate::operators::Operators;

// Rows from which the products with `L` run on the rayon pool
// (the iteration's shared threshold, crates/dend/src/deform/parallel.rs).
use super::parallel::PARALLEL_MIN_VERTICES as PARALLEL_MIN;
/// Rows per task of the parallel products.
const CHUNK: usize = 1024;

/// `(M x)_i` for a CSR matrix `m` whose entry `(i, j)` is scaled by
/// `col_scale[j]` when given.
#[inline(always)]
fn row_product(m: &CsMat<Real>, i: usize, x: &[Point], col_scale: Option<&[Real]>) -> Point {
    let (lo, hi) = (m.indptr().index(i), m.indptr().index(i + 1));
    let mut acc = [0.0; 3];
    for (&j, &v) in m.indices()[lo..hi].iter().zip(&m.data()[lo..hi]) {
        let w = match col_scale {
            Some(s) => v * s[j],
            None => v,
        };
        let xj = x[j];
        acc[0] += w * xj[0];
        acc[1] += w * xj[1];
        acc[2] += w * xj[2];
    }
    acc
}

/// `out[i] = f(i)` for every row, in parallel chunks on long vectors.
fn for_each_row(out: &mut [Point], f: impl Fn(usize) -> Point + Sync) {
    if out.len() >= PARALLEL_MIN {
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, o)| {
            for (k, v) in o.iter_mut().enumerate() {
                *v = f(c * CHUNK + k);
            }
        });
    } else {
        for (i, v) in out.iter_mut().enumerate() {
            *v = f(i);
        }
    }
}

/// `out = L x` on every row.
pub(crate) fn mul_l(ops: &Operators, x: &[Point], out: &mut [Point]) {
    for_each_row(out, |i| row_product(&ops.l, i, x, None));
}

/// `(L x)_i`.
#[inline]
pub(crate) fn l_row(ops: &Operators, i: usize, x: &[Point]) -> Point {
    row_product(&ops.l, i, x, None)
}

/// `(Lᵀ x)_i = (Lbar D x)_i`.
#[inline]
pub(crate) fn lt_row(ops: &Operators, i: usize, x: &[Point]) -> Point {
    row_product(&ops.lbar, i, x, Some(&ops.inv_area))
}

/// `x = Pᵀ u + v` on every row for `A = P L`, or `x = Lᵀ u + v` for
/// [`Shape::Right`], in one pass; `lu` receives `Lᵀ u` where it is needed
/// (`cl ≠ 0`, or [`Shape::Right`], whose gradient uses it again).
pub(crate) fn inner_gradient(
    shape: Shape,
    ops: &Operators,
    u: &[Point],
    v: &[Point],
    lu: &mut [Point],
    x: &mut [Point],
) {
    let (ci, cl, g) = match shape {
        Shape::Left { ci, cl, g } => (ci, cl, g),
        Shape::Right => (0.0, 1.0, 0.0),
    };
    let row = |i: usize, lui: Point| -> Point {
        let s = ci - 2.0 * g * ops.g[i];
        let (ui, vi) = (u[i], v[i]);
        [
            s * ui[0] + cl * lui[0] + vi[0],
            s * ui[1] + cl * lui[1] + vi[1],
            s * ui[2] + cl * lui[2] + vi[2],
        ]
    };
    let n = x.len();
    let work = |start: usize, x: &mut [Point], lu: &mut [Point]| {
        for (k, (xi, li)) in x.iter_mut().zip(lu.iter_mut()).enumerate() {
            let i = start + k;
            let lui = if cl == 0.0 {
                [0.0; 3]
            } else {
                lt_row(ops, i, u)
            };
            *li = lui;
            *xi = row(i, lui);
        }
    };
    if n >= PARALLEL_MIN {
        x.par_chunks_mut(CHUNK)
            .zip(lu.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (x, lu))| work(c * CHUNK, x, lu));
    } else {
        work(0, x, lu);
    }
}

/// `(P e)_i` for `A = P L`.
#[inline]
pub(crate) fn p_row(shape: Shape, ops: &Operators, i: usize, e: &[Point]) -> Point {
    let Shape::Left { ci, cl, g } = shape else {
        unreachable!("p_row is only called for A = P L");
    };
    let s = ci - 2.0 * g * ops.g[i];
    let ei = e[i];
    if cl == 0.0 {
        return [s * ei[0], s * ei[1], s * ei[2]];
    }
    let le = l_row(ops, i, e);
    [
        s * ei[0] + cl * le[0],
        s * ei[1] + cl * le[1],
        s * ei[2] + cl * le[2],
    ]
}
