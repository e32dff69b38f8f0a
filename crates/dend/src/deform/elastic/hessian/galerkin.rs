//! The Newton matrix projected onto the rigid motions of aggregates of
//! vertices: the Galerkin coarse operator `G = Pᵀ H P` of a coarse
//! correction (`solver/galerkin.rs`).
//!
//! Each unknown `k` belongs to one aggregate `a(k)`, and the coarse space
//! moves each aggregate by a translation `t_a` and a small turn `ω_a`
//! about a centre `c_a`:
//!
//! ```text
//! ΔY_k = t_a + ω_a × r_k = P_k [t_a; ω_a],   P_k = [I | −[r_k]×],   r_k = y_k − c_a
//! ```
//!
//! (the rigid body modes of smoothed-aggregation multigrid for elasticity,
//! Vaněk, Mandel & Brezina 1996; Xian, Tong & Liu 2019 build a Galerkin
//! coarse operator from a skinning-like space the same way). `H = Q ⊗ I +
//! Σ_e B_e` is the Newton matrix of `solver/newton.rs` ([`Curvature`]),
//! and every element's `B_e` has a low rank, so `G` is assembled from
//! the elements' factors without forming `H`:
//!
//! - a row `k` of `Q`: `Σ_l q_kl P_kᵀ P_l`, per aggregate `b` of the
//!   `l`s `[[s I, −[v]×], [s [r_k]×, −[r_k]×[v]×]]` with `s = Σ q_kl`,
//!   `v = Σ q_kl r_l`;
//! - a vertex `i`: `−(J P)ᵀ C⁻¹ (J P)`, `(J P)_b = Σ_{k ∈ b} J_k P_k`;
//! - a triangle: `Σ w λ (Pᵀ Aᵀ m)(Pᵀ Aᵀ m)ᵀ − w Σ_d F_dᵀ F_d` with
//!   `F_{d,b} = Σ_{k ∈ b} κ_{kd} P_k` (`Q`'s `w AᵀA` taken out).
//!
//! Each block row (an aggregate) is summed by one task, elements in
//! order, so `G` is the same to the bit for any number of threads; an
//! element touching `m` aggregates is evaluated `m` times.

use nalgebra::{Matrix3, SMatrix, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::blocks::{triangle_modes, Elements};
use super::{cross_matrix, Curvature};
use crate::deform::elastic::ElasticOps;
use crate::mesh::{Point, Real};
use crate::operators::Operators;

/// `3 × 6`: one unknown's `P_k`, or a sum of them.
pub(crate) type M36 = SMatrix<Real, 3, 6>;
/// `6 × 6`: one block of `G`.
pub(crate) type M6 = SMatrix<Real, 6, 6>;

/// An element's sums per aggregate: `(aggregate, Σ_k X_k P_k)`.
type Parts = Vec<(u32, M36)>;

/// The aggregates of one constraint set and the pattern of `G`.
#[derive(Debug, Clone)]
pub(crate) struct RigidSpace {
    /// Each unknown's aggregate.
    pub(crate) agg: Vec<u32>,
    /// Each aggregate's unknowns (CSR).
    pub(crate) uptr: Vec<usize>,
    pub(crate) unknowns: Vec<u32>,
    /// Each aggregate's elements, ascending (CSR): those with an unknown
    /// of the aggregate in their support.
    eptr: Vec<usize>,
    elems: Vec<u32>,
    /// `G`'s block pattern (CSR over aggregates, both triangles, sorted).
    ptr: Vec<usize>,
    cols: Vec<u32>,
}

/// `P_k = [I | −[r]×]`.
fn rigid(r: &Vector3<Real>) -> M36 {
    let mut m = M36::zeros();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    m.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-cross_matrix(r)));
    m
}

impl RigidSpace {
    /// The space of the aggregates `agg` (one per unknown, `0..n_agg`)
    /// for the elements `els` and `Q`'s pattern `q` (unknowns × unknowns).
    pub(crate) fn new(agg: Vec<u32>, n_agg: usize, els: &Elements, q: &sprs::CsMat<Real>) -> Self {
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); n_agg];
        for (k, &a) in agg.iter().enumerate() {
            members[a as usize].push(k as u32);
        }
        let (uptr, unknowns) = csr(members);
        let mut of_elem: Vec<Vec<u32>> = vec![Vec::new(); n_agg];
        let mut rows: Vec<Vec<u32>> = vec![Vec::new(); n_agg];
        let mut touched = Vec::new();
        for e in 0..els.len() {
            touched.clear();
            touched.extend(els.unknowns(e).map(|k| agg[k as usize]));
            touched.sort_unstable();
            touched.dedup();
            for &a in &touched {
                of_elem[a as usize].push(e as u32);
                rows[a as usize].extend(&touched);
            }
        }
        for (k, row) in q.outer_iterator().enumerate() {
            let a = agg[k] as usize;
            rows[a].extend(row.indices().iter().map(|&l| agg[l]));
        }
        for row in &mut rows {
            row.sort_unstable();
            row.dedup();
        }
        let (eptr, elems) = csr(of_elem);
        let (ptr, cols) = csr(rows);
        RigidSpace {
            agg,
            uptr,
            unknowns,
            eptr,
            elems,
            ptr,
            cols,
        }
    }

    /// How many aggregates there are.
    pub(crate) fn len(&self) -> usize {
        self.uptr.len() - 1
    }

    /// `G`'s scalar pattern (`6 n_agg` square, both triangles, sorted
    /// rows), its values zero: aggregate `a`'s six rows are contiguous,
    /// each with six columns per block of its block row.
    pub(crate) fn pattern(&self) -> sprs::CsMat<Real> {
        let n = 6 * self.len();
        let mut indptr = Vec::with_capacity(n + 1);
        let mut indices = Vec::new();
        indptr.push(0);
        for a in 0..self.len() {
            let row = &self.cols[self.ptr[a]..self.ptr[a + 1]];
            for _ in 0..6 {
                for &b in row {
                    indices.extend((0..6).map(|j| 6 * b as usize + j));
                }
                indptr.push(indices.len());
            }
        }
        let data = vec![0.0; indices.len()];
        sprs::CsMat::new((n, n), indptr, indices, data)
    }
}

/// A CSR of lists.
fn csr(lists: Vec<Vec<u32>>) -> (Vec<usize>, Vec<u32>) {
    let mut ptr = Vec::with_capacity(lists.len() + 1);
    ptr.push(0);
    let mut out = Vec::new();
    for l in lists {
        out.extend(l);
        ptr.push(out.len());
    }
    (ptr, out)
}

impl ElasticOps {
    /// Writes `G = Pᵀ H P` (module docs) into `g`'s values
    /// ([`RigidSpace::pattern`]), `H` with `curvature`, at the normalised
    /// pose `y`, rotations `rot` and area targets `proj`, with each
    /// unknown's lever arm `r_k` in `lever` and `Q_UU` in `q`; on the rayon
    /// pool.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn galerkin_matrix(
        &self,
        space: &RigidSpace,
        els: &Elements,
        ops: &Operators,
        q: &sprs::CsMat<Real>,
        (y, rot, proj): (&[Point], &[UnitQuaternion<Real>], &[[Real; 6]]),
        lever: &[Vector3<Real>],
        curvature: Curvature,
        g: &mut sprs::CsMat<Real>,
    ) {
        // the block rows' disjoint value slices
        let mut tasks = Vec::with_capacity(space.len());
        let mut rest = g.data_mut();
        for a in 0..space.len() {
            let len = 36 * (space.ptr[a + 1] - space.ptr[a]);
            let (row, tail) = rest.split_at_mut(len);
            tasks.push((a, row));
            rest = tail;
        }
        tasks.into_par_iter().for_each_init(
            || (Vec::new(), Vec::new(), Vec::new()),
            |(blocks, j, parts), (a, out)| {
                let cols = &space.cols[space.ptr[a]..space.ptr[a + 1]];
                blocks.clear();
                blocks.resize(cols.len(), M6::zeros());
                let at = |b: u32| cols.binary_search(&b).expect("a block of the pattern");
                self.q_rows(space, a, q, lever, &at, blocks);
                for &e in &space.elems[space.eptr[a]..space.eptr[a + 1]] {
                    self.element_rows(
                        space,
                        els,
                        ops,
                        e as usize,
                        a as u32,
                        (y, rot, proj),
                        lever,
                        curvature,
                        (&at, j, parts),
                        blocks,
                    );
                }
                let n = cols.len();
                for (c, blk) in blocks.iter().enumerate() {
                    for i in 0..6 {
                        for jj in 0..6 {
                            out[i * 6 * n + 6 * c + jj] = blk[(i, jj)];
                        }
                    }
                }
            },
        );
    }

    /// Adds the rows of `Q` of aggregate `a`'s unknowns (module docs).
    fn q_rows(
        &self,
        space: &RigidSpace,
        a: usize,
        q: &sprs::CsMat<Real>,
        lever: &[Vector3<Real>],
        at: &dyn Fn(u32) -> usize,
        blocks: &mut [M6],
    ) {
        let mut acc: Vec<(u32, Real, Vector3<Real>)> = Vec::new();
        for &k in &space.unknowns[space.uptr[a]..space.uptr[a + 1]] {
            let k = k as usize;
            acc.clear();
            let row = q.outer_view(k).expect("a row of Q");
            for (l, &v) in row.iter() {
                let b = space.agg[l];
                match acc.iter_mut().find(|x| x.0 == b) {
                    Some(x) => {
                        x.1 += v;
                        x.2 += v * lever[l];
                    }
                    None => acc.push((b, v, v * lever[l])),
                }
            }
            let rk = cross_matrix(&lever[k]);
            for &(b, s, v) in &acc {
                let vx = cross_matrix(&v);
                let blk = &mut blocks[at(b)];
                let mut m = M6::zeros();
                m.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&(Matrix3::identity() * s));
                m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-vx));
                m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(rk * s));
                m.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-(rk * vx)));
                *blk += m;
            }
        }
    }

    /// Adds element `e`'s blocks of block row `a` (module docs).
    #[allow(clippy::too_many_arguments)]
    fn element_rows(
        &self,
        space: &RigidSpace,
        els: &Elements,
        ops: &Operators,
        e: usize,
        a: u32,
        (y, rot, proj): (&[Point], &[UnitQuaternion<Real>], &[[Real; 6]]),
        lever: &[Vector3<Real>],
        curvature: Curvature,
        (at, j, parts): (&dyn Fn(u32) -> usize, &mut Vec<Matrix3<Real>>, &mut Parts),
        blocks: &mut [M6],
    ) {
        let (support, unknown) = els.support(e);
        // the element's aggregates, with a sum per aggregate
        let slot = |b: u32, parts: &mut Parts| -> usize {
            match parts.iter().position(|p| p.0 == b) {
                Some(s) => s,
                None => {
                    parts.push((b, M36::zeros()));
                    parts.len() - 1
                }
            }
        };
        parts.clear();
        if let Some(i) = els.vertex(e) {
            let (c_inv, _) = self.vertex_coupling(ops, i, support, (y, &rot[i]), curvature, j);
            let Some(c_inv) = c_inv else { return };
            for (s, &k) in unknown.iter().enumerate() {
                if k == u32::MAX {
                    continue;
                }
                let p = slot(space.agg[k as usize], parts);
                parts[p].1 += j[s] * rigid(&lever[k as usize]);
            }
            let Some(me) = parts.iter().position(|p| p.0 == a) else {
                return;
            };
            let left = (c_inv * parts[me].1).transpose();
            for (b, u) in parts.iter() {
                blocks[at(*b)] -= left * u;
            }
        } else {
            let t = e - els.num_vertices();
            let el = &self.area[t];
            let k = el.corners();
            let w = el.weight;
            // −w Σ_d F_dᵀ F_d
            for d in [0, 1] {
                parts.clear();
                for (c, &u) in unknown.iter().enumerate() {
                    if u == u32::MAX {
                        continue;
                    }
                    let p = slot(space.agg[u as usize], parts);
                    parts[p].1 += k[c][d] * rigid(&lever[u as usize]);
                }
                let Some(me) = parts.iter().position(|p| p.0 == a) else {
                    return;
                };
                let left = w * parts[me].1.transpose();
                for (b, f) in parts.iter() {
                    blocks[at(*b)] -= left * f;
                }
            }
            triangle_modes(el, y, &proj[t], curvature, |wl, am| {
                let mut g: [(u32, SMatrix<Real, 6, 1>); 3] = [(u32::MAX, SMatrix::zeros()); 3];
                let mut ng = 0;
                for (c, &u) in unknown.iter().enumerate() {
                    if u == u32::MAX {
                        continue;
                    }
                    let b = space.agg[u as usize];
                    let v = rigid(&lever[u as usize]).transpose() * am[c];
                    match g[..ng].iter_mut().find(|x| x.0 == b) {
                        Some(x) => x.1 += v,
                        None => {
                            g[ng] = (b, v);
                            ng += 1;
                        }
                    }
                }
                if let Some(me) = g[..ng].iter().position(|x| x.0 == a) {
                    let left = wl * g[me].1;
                    for (b, v) in &g[..ng] {
                        blocks[at(*b)] += left * v.transpose();
                    }
                }
            });
        }
    }
}
