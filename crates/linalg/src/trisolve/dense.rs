//! One wide supernode swept on two threads.
//!
//! The supernodes above [`super::SolvePlan`]'s frontier (the top
//! separators: a dense root and a few wide nodes, 12–18 % of the factor's
//! values on the meshes measured) have no independent subtrees left, so the
//! plan used to sweep them on one thread. Inside one supernode the work
//! still splits: in panels of [`PANEL`] columns, the panel's own triangle
//! is solved on one thread, then its update of (forward) or the dot
//! products with (backward) the rows below it are split between two
//! threads by rows (one `rayon::join` per panel; the classic blocked
//! triangular solve, e.g. Golub & Van Loan §3.1).

use super::sweep::{dots_block, triangle_backward, triangle_forward, update_block};
use super::types::{FactorValue, Lanes, Rows, Supernodal};
use crate::cpu::has_fma;

/// Columns per panel: one `rayon::join` per panel and sweep.
pub(crate) const PANEL: usize = 32;

/// Column blocks `(j0, k)` of four inside the panel `pc..pe`.
fn panel_blocks(
    pc: usize,
    pe: usize,
) -> impl DoubleEndedIterator<Item = (usize, usize)> + ExactSizeIterator {
    (pc..pe).step_by(4).map(move |j0| (j0, (pe - j0).min(4)))
}

/// The forward sweep of supernode `s` (rows owned by the caller, off-diagonal
/// updates scattered directly).
pub(crate) fn forward_node<V: FactorValue>(
    f: Supernodal<'_, V>,
    s: usize,
    x: Rows,
    tmp: &mut [Lanes],
) {
    if has_fma() {
        forward_node_impl::<V, true>(f, s, x, tmp);
    } else {
        forward_node_impl::<V, false>(f, s, x, tmp);
    }
}

/// The backward sweep of supernode `s`.
pub(crate) fn backward_node<V: FactorValue>(
    f: Supernodal<'_, V>,
    s: usize,
    x: Rows,
    tmp: &mut [Lanes],
) {
    if has_fma() {
        backward_node_impl::<V, true>(f, s, x, tmp);
    } else {
        backward_node_impl::<V, false>(f, s, x, tmp);
    }
}

fn forward_node_impl<V: FactorValue, const SIMD: bool>(
    f: Supernodal<'_, V>,
    s: usize,
    x: Rows,
    tmp: &mut [Lanes],
) {
    let (c0, w, pattern, block) = f.node(s);
    let h = w + pattern.len();
    let t = &mut tmp[..pattern.len()];
    t.fill([0.0; 4]);
    // SAFETY: the caller owns supernode s's rows and its pattern's rows.
    let xs = unsafe { x.slice(c0, w) };
    for pc in (0..w).step_by(PANEL) {
        let pe = (pc + PANEL).min(w);
        // the panel: its triangle and its update of its own rows
        for (j0, k) in panel_blocks(pc, pe) {
            triangle_forward(block, h, (j0, k), xs);
            let (head, below) = xs.split_at_mut(j0 + k);
            update_block::<V, SIMD, false>(
                block,
                h,
                (j0, k),
                j0 + k,
                &head[j0..],
                &mut below[..pe - (j0 + k)],
            );
        }
        // the rows below the panel, [pe, h) in block rows, in two halves
        let (head, below) = xs.split_at_mut(pe);
        let solved = &head[pc..pe];
        let mid = pe + (h - pe) / 2;
        let (xa, xb) = below.split_at_mut(mid.min(w) - pe);
        let (ta, tb) = t.split_at_mut(mid.max(w) - w);
        let part = |xr: &mut [Lanes], x0: usize, tr: &mut [Lanes], t0: usize| {
            for (j0, k) in panel_blocks(pc, pe) {
                let xj = &solved[j0 - pc..];
                update_block::<V, SIMD, false>(block, h, (j0, k), x0, xj, xr);
                update_block::<V, SIMD, true>(block, h, (j0, k), w + t0, xj, tr);
            }
        };
        let b0 = mid.min(w);
        let tb0 = mid.max(w) - w;
        rayon::join(|| part(xa, pe, ta, 0), || part(xb, b0, tb, tb0));
    }
    for (ti, &r) in t.iter().zip(pattern) {
        // SAFETY: the caller owns the pattern's rows.
        unsafe { x.sub(r, *ti) };
    }
}

fn backward_node_impl<V: FactorValue, const SIMD: bool>(
    f: Supernodal<'_, V>,
    s: usize,
    x: Rows,
    tmp: &mut [Lanes],
) {
    let (c0, w, pattern, block) = f.node(s);
    let h = w + pattern.len();
    let t = &mut tmp[..pattern.len()];
    for (ti, &r) in t.iter_mut().zip(pattern) {
        // SAFETY: the ancestors' rows are final and nobody writes them now.
        *ti = unsafe { x.get(r) };
    }
    let t: &[Lanes] = t;
    // SAFETY: the caller owns supernode s's rows.
    let xs = unsafe { x.slice(c0, w) };
    for pc in (0..w.div_ceil(PANEL)).rev().map(|b| b * PANEL) {
        let pe = (pc + PANEL).min(w);
        let (head, below) = xs.split_at_mut(pe);
        let below: &[Lanes] = below;
        // dot products of the panel's columns with the final rows [pe, h)
        let mid = pe + (h - pe) / 2;
        let (xa, xb) = below.split_at(mid.min(w) - pe);
        let (ta, tb) = t.split_at(mid.max(w) - w);
        let part = |xr: &[Lanes], x0: usize, tr: &[Lanes], t0: usize| {
            let mut acc = [[[0.0; 4]; 4]; PANEL / 4];
            for (b, (j0, k)) in panel_blocks(pc, pe).enumerate() {
                let d1 = dots_block::<V, SIMD>(block, h, (j0, k), x0, xr);
                let d2 = dots_block::<V, SIMD>(block, h, (j0, k), w + t0, tr);
                for c in 0..4 {
                    for q in 0..4 {
                        acc[b][c][q] = d1[c][q] + d2[c][q];
                    }
                }
            }
            acc
        };
        let (b0, tb0) = (mid.min(w), mid.max(w) - w);
        let (a1, a2) = rayon::join(|| part(xa, pe, ta, 0), || part(xb, b0, tb, tb0));
        // the panel itself, last block first
        for (b, (j0, k)) in panel_blocks(pc, pe).enumerate().rev() {
            let (blk, within) = head.split_at_mut(j0 + k);
            let within: &[Lanes] = &within[..pe - (j0 + k)];
            let diag = dots_block::<V, SIMD>(block, h, (j0, k), j0 + k, within);
            for c in 0..k {
                for q in 0..4 {
                    blk[j0 + c][q] -= a1[b][c][q] + a2[b][c][q] + diag[c][q];
                }
            }
            triangle_backward(block, h, (j0, k), blk);
        }
    }
}
