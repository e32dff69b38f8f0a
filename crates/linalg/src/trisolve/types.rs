//! What the sweeps work on: the factor's stored values and supernodes,
//! the solution rows (four right-hand-side lanes each, shared by the
//! threads of a parallel sweep) and where a forward sweep's updates go.

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

use crate::Real;

/// Four right-hand-side lanes of one row.
pub(crate) type Lanes = [Real; 4];

/// A stored factor value: `f64`, or `f32` widened on load
/// (`dend::deform::FactorPrecision`). The arithmetic is `f64` either way.
pub trait FactorValue: Copy + Send + Sync {
    /// The value widened to `f64`.
    fn get(self) -> Real;
}

impl FactorValue for f64 {
    #[inline(always)]
    fn get(self) -> Real {
        self
    }
}

impl FactorValue for f32 {
    #[inline(always)]
    fn get(self) -> Real {
        self as Real
    }
}

/// A supernodal factor: faer's symbolic structure and the values (per
/// supernode a column-major block, the diagonal block on top of the
/// off-diagonal rows).
#[derive(Clone, Copy)]
pub struct Supernodal<'a, V> {
    /// faer's supernodal structure.
    pub sym: &'a SymbolicSupernodalCholesky<usize>,
    /// The values, supernode after supernode.
    pub values: &'a [V],
}

impl<V: FactorValue> Supernodal<'_, V> {
    /// Columns `begin..begin + width`, off-diagonal row pattern and value
    /// block of supernode `s`.
    #[inline(always)]
    pub(super) fn node(&self, s: usize) -> (usize, usize, &[usize], &[V]) {
        let sym = self.sym;
        let begin = sym.supernode_begin()[s];
        let width = sym.supernode_end()[s] - begin;
        let cpr = sym.col_ptr_for_row_idx();
        let cpv = sym.col_ptr_for_val();
        (
            begin,
            width,
            &sym.row_idx()[cpr[s]..cpr[s + 1]],
            &self.values[cpv[s]..cpv[s + 1]],
        )
    }
}

/// The solution rows, shared by the threads of a parallel sweep.
///
/// Each thread writes only the rows of its own supernodes (its subtrees of
/// the elimination tree) and reads only those and rows no thread writes in
/// that phase; [`parallel`] establishes this and the sequential sweeps are
/// trivially exclusive.
#[derive(Clone, Copy)]
pub(crate) struct Rows {
    ptr: *mut Lanes,
    len: usize,
}

// SAFETY: `Rows` is a view of a `&mut [Lanes]` that outlives every use;
// concurrent uses touch disjoint rows (type docs).
unsafe impl Send for Rows {}
unsafe impl Sync for Rows {}

impl Rows {
    pub(crate) fn new(x: &mut [Lanes]) -> Self {
        Rows {
            ptr: x.as_mut_ptr(),
            len: x.len(),
        }
    }

    /// Rows `start..start + len`.
    ///
    /// # Safety
    /// No other live reference or thread may access these rows.
    #[inline(always)]
    #[allow(clippy::mut_from_ref)]
    pub(super) unsafe fn slice(&self, start: usize, len: usize) -> &mut [Lanes] {
        assert!(start + len <= self.len);
        std::slice::from_raw_parts_mut(self.ptr.add(start), len)
    }

    /// Row `r`.
    ///
    /// # Safety
    /// No other thread may write row `r` concurrently.
    #[inline(always)]
    pub(super) unsafe fn get(&self, r: usize) -> Lanes {
        assert!(r < self.len);
        *self.ptr.add(r)
    }

    /// `x[r] -= v`.
    ///
    /// # Safety
    /// No other thread may access row `r` concurrently.
    #[inline(always)]
    pub(super) unsafe fn sub(&self, r: usize, v: Lanes) {
        assert!(r < self.len);
        let xr = &mut *self.ptr.add(r);
        for k in 0..4 {
            xr[k] -= v[k];
        }
    }
}

/// Where a forward sweep sends a supernode's update of rows outside it.
pub(crate) enum Scatter<'a> {
    /// Straight into the solution (a single thread owns every row).
    Direct,
    /// Rows of thread `me` directly; rows of the shared ancestors into the
    /// thread's own accumulator `delta`, indexed by `top_index`.
    Split {
        me: u8,
        owner: &'a [u8],
        top_index: &'a [u32],
        delta: &'a mut [Lanes],
    },
}

/// Solves `b` four columns at a time: each group gathered into `x` in the
/// factor's row order (`perm`'s forward array), solved in place by
/// `solve`, and scattered back through its inverse.
#[inline(always)]
pub(crate) fn by_four_columns(
    mut b: faer::MatMut<'_, Real>,
    perm: Option<faer::perm::PermRef<'_, usize>>,
    x: &mut [Lanes],
    mut solve: impl FnMut(&mut [Lanes]),
) {
    let n = x.len();
    let (fwd, inv) = match perm {
        Some(p) => {
            let (f, i) = p.arrays();
            (Some(f), Some(i))
        }
        None => (None, None),
    };
    for c0 in (0..b.ncols()).step_by(4) {
        let k = (b.ncols() - c0).min(4);
        for (i, xi) in x.iter_mut().enumerate() {
            let src = fwd.map_or(i, |f| f[i]);
            *xi = [0.0; 4];
            for l in 0..k {
                xi[l] = b[(src, c0 + l)];
            }
        }
        solve(x);
        for i in 0..n {
            let xi = x[inv.map_or(i, |v| v[i])];
            for l in 0..k {
                b[(i, c0 + l)] = xi[l];
            }
        }
    }
}
