//! The Newton matrix projected onto blended rigid motions of aggregates
//! of vertices: the Galerkin coarse operator `G = Pᵀ H P` of a coarse
//! correction (`solver/galerkin.rs`).
//!
//! Each aggregate `a` moves by a translation `t_a` and a small turn `ω_a`
//! about a centre `c_a`, and each unknown `k` blends the motions of the
//! aggregates it has a weight in (`w_ka ≥ 0`, `Σ_a w_ka = 1`):
//!
//! ```text
//! ΔY_k = Σ_a w_ka (t_a + ω_a × r_ka) = P_k [t; ω],   P_ka = w_ka [I | −[r_ka]×],   r_ka = y_k − c_a
//! ```
//!
//! With one weight per unknown (a partition) these are the rigid body
//! modes of aggregation multigrid for elasticity (Vaněk, Mandel & Brezina
//! 1996); weights smoothed across the aggregates' borders blend them like
//! a skinning, the prolongation of Xian, Tong & Liu 2019, so that a
//! coarse motion does not kink where two aggregates meet. The weights sum
//! to one, so the motions of the whole shape stay in the space.
//! `H = Q ⊗ I + Σ_e B_e` is the Newton matrix of `solver/newton.rs`
//! ([`Curvature`]), and every element's `B_e` has a low rank, so `G` is
//! assembled from the elements' factors without forming `H`:
//!
//! - a row `k` of `Q'`: `Σ_l q'_kl P_kᵀ P_l`, per aggregates `a` of `k` and
//!   `b` of the `l`s `w_ka [[s I, −[v]×], [s [r_ka]×, −[r_ka]×[v]×]]` with
//!   `s = Σ_l q'_kl w_lb`, `v = Σ_l q'_kl w_lb r_lb`;
//! - a vertex `i`: `−(J P)ᵀ C⁻¹ (J P)`, `(J P)_b = Σ_k J_k P_kb`;
//! - a triangle: `Σ w λ (Pᵀ Aᵀ m)(Pᵀ Aᵀ m)ᵀ`.
//!
//! `Q' = Q − Σ_t w_t A_tᵀ A_t` ([`ElasticOps::without_area`]): a
//! triangle's curvature is `w (AᵀA − λ (Aᵀm)(Aᵀm)ᵀ)` minus what `Q`
//! holds of it, `w AᵀA`, so the constant part cancels in `Q'`, once per
//! constraint set, and each assembly sums the pose's modes only.
//!
//! Each group of neighbouring aggregates ([`GROUP`], renumbered to a
//! range) is summed by one task, elements in order, so `G` is the same to
//! the bit for any number of threads; an element is evaluated once per
//! group it touches.

use nalgebra::{Matrix3, SMatrix, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::blocks::{triangle_modes, Elements};
use super::{cross_matrix, Curvature};
use crate::deform::elastic::ElasticOps;
use crate::mesh::{Point, Real};
use crate::operators::Operators;

/// `3 × 6`: one `P_ka`, or a sum of them.
pub(crate) type M36 = SMatrix<Real, 3, 6>;
/// `6 × 6`: one block of `G`.
pub(crate) type M6 = SMatrix<Real, 6, 6>;
/// `6 × 1`: one aggregate's part of `Pᵀ v`.
type V6 = SMatrix<Real, 6, 1>;

/// The scratch of one task of [`ElasticOps::galerkin_matrix`].
type Scratch = (Vec<M6>, Vec<Matrix3<Real>>, Vec<(u32, M36)>, Vec<(u32, V6)>);

/// What [`ElasticOps::element_rows`] is given: where a block is, and its
/// scratch (`J`, the parts and the modes per aggregate).
type ElementScratch<'a> = (
    &'a dyn Fn(u32, u32) -> usize,
    &'a mut Vec<Matrix3<Real>>,
    &'a mut Vec<(u32, M36)>,
    &'a mut Vec<(u32, V6)>,
);

/// Each unknown's aggregates and weights (CSR over the unknowns): the
/// prolongation's entries `(k, a, w_ka)`, `Σ_a w_ka = 1` for each `k`.
#[derive(Debug, Clone)]
pub(crate) struct Weights {
    pub(crate) ptr: Vec<usize>,
    pub(crate) agg: Vec<u32>,
    pub(crate) w: Vec<Real>,
}

impl Weights {
    /// One aggregate per unknown, weight one (`agg[k]` for unknown `k`).
    pub(crate) fn partition(agg: Vec<u32>) -> Self {
        Weights {
            ptr: (0..=agg.len()).collect(),
            w: vec![1.0; agg.len()],
            agg,
        }
    }

    /// How many unknowns there are.
    pub(crate) fn num_unknowns(&self) -> usize {
        self.ptr.len() - 1
    }

    /// Unknown `k`'s entries (indices into `agg` and `w`).
    pub(crate) fn entries(&self, k: usize) -> std::ops::Range<usize> {
        self.ptr[k]..self.ptr[k + 1]
    }
}

/// The aggregates of one constraint set, their weights and the pattern of
/// `G`.
#[derive(Debug, Clone)]
pub(crate) struct RigidSpace {
    /// The prolongation's weights (module docs); an entry's lever arm
    /// `r_ka` is at the same index in the lever arms.
    pub(crate) weights: Weights,
    /// Each entry's unknown.
    pub(crate) entry_unknown: Vec<u32>,
    /// Each aggregate's entries (CSR), by unknown ascending.
    pub(crate) aptr: Vec<usize>,
    pub(crate) aentries: Vec<u32>,
    /// The groups of aggregates one task of the assembly sums (each a
    /// range of aggregates: group `g` is `gptr[g]..gptr[g + 1]`).
    gptr: Vec<usize>,
    /// Each group's elements, ascending (CSR): those with an unknown
    /// weighted in one of its aggregates in their support.
    geptr: Vec<usize>,
    gelems: Vec<u32>,
    /// `G`'s block pattern (CSR over aggregates, both triangles, sorted).
    ptr: Vec<usize>,
    cols: Vec<u32>,
}

/// The slot of aggregate `b` in a short list of sums per aggregate,
/// added (as `zero`) if new.
pub(crate) fn slot<T: Copy>(parts: &mut Vec<(u32, T)>, b: u32, zero: T) -> usize {
    match parts.iter().position(|p| p.0 == b) {
        Some(s) => s,
        None => {
            parts.push((b, zero));
            parts.len() - 1
        }
    }
}

impl RigidSpace {
    /// The space of the weights `weights` over `n_agg` aggregates for the
    /// elements `els` and `Q`'s pattern `q` (unknowns × unknowns). The
    /// aggregates are renumbered so that each group of neighbours the
    /// assembly sums in one task is a range ([`GROUP`]).
    pub(crate) fn new(
        weights: Weights,
        n_agg: usize,
        els: &Elements,
        q: &sprs::CsMat<Real>,
    ) -> Self {
        Self::with_groups(weights, n_agg, els, q, GROUP)
    }

    /// [`RigidSpace::new`] with groups of at most `group` aggregates.
    pub(crate) fn with_groups(
        mut weights: Weights,
        n_agg: usize,
        els: &Elements,
        q: &sprs::CsMat<Real>,
        group: usize,
    ) -> Self {
        let rows = block_rows(&weights, n_agg, els, q);
        // greedy groups of neighbouring aggregates, numbered in order
        let mut new_id = vec![u32::MAX; n_agg];
        let mut gptr = vec![0];
        let mut next = 0u32;
        for a in 0..n_agg {
            if new_id[a] != u32::MAX {
                continue;
            }
            new_id[a] = next;
            next += 1;
            for &b in &rows[a] {
                if next as usize - gptr[gptr.len() - 1] >= group.max(1) {
                    break;
                }
                if new_id[b as usize] == u32::MAX {
                    new_id[b as usize] = next;
                    next += 1;
                }
            }
            gptr.push(next as usize);
        }
        for a in weights.agg.iter_mut() {
            *a = new_id[*a as usize];
        }
        let rows = block_rows(&weights, n_agg, els, q);
        let nu = weights.num_unknowns();
        let mut entry_unknown = vec![0u32; weights.agg.len()];
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); n_agg];
        for k in 0..nu {
            for e in weights.entries(k) {
                entry_unknown[e] = k as u32;
                members[weights.agg[e] as usize].push(e as u32);
            }
        }
        let (aptr, aentries) = csr(members);
        let mut group_of = vec![0u32; n_agg];
        for g in 0..gptr.len() - 1 {
            group_of[gptr[g]..gptr[g + 1]].fill(g as u32);
        }
        let mut of_group: Vec<Vec<u32>> = vec![Vec::new(); gptr.len() - 1];
        let mut touched = Vec::new();
        for e in 0..els.len() {
            touched.clear();
            touched.extend(
                els.unknowns(e)
                    .flat_map(|k| weights.agg[weights.entries(k as usize)].iter())
                    .map(|&a| group_of[a as usize]),
            );
            touched.sort_unstable();
            touched.dedup();
            for &g in &touched {
                of_group[g as usize].push(e as u32);
            }
        }
        let (geptr, gelems) = csr(of_group);
        let (ptr, cols) = csr(rows);
        RigidSpace {
            weights,
            entry_unknown,
            aptr,
            aentries,
            gptr,
            geptr,
            gelems,
            ptr,
            cols,
        }
    }

    /// How many aggregates there are.
    pub(crate) fn len(&self) -> usize {
        self.aptr.len() - 1
    }

    /// Aggregate `a`'s entries.
    pub(crate) fn members(&self, a: usize) -> &[u32] {
        &self.aentries[self.aptr[a]..self.aptr[a + 1]]
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

/// Aggregates per task of [`ElasticOps::galerkin_matrix`]: an element is
/// evaluated once per group it touches, so larger groups evaluate fewer
/// elements twice, and smaller ones balance the threads better.
const GROUP: usize = 16;

/// `G`'s block pattern: each aggregate's neighbours (sorted), those
/// sharing an element or an entry of `Q` with it.
fn block_rows(
    weights: &Weights,
    n_agg: usize,
    els: &Elements,
    q: &sprs::CsMat<Real>,
) -> Vec<Vec<u32>> {
    let aggs_of = |k: u32| weights.agg[weights.entries(k as usize)].iter().copied();
    let mut rows: Vec<Vec<u32>> = vec![Vec::new(); n_agg];
    let mut touched = Vec::new();
    for e in 0..els.len() {
        touched.clear();
        touched.extend(els.unknowns(e).flat_map(aggs_of));
        touched.sort_unstable();
        touched.dedup();
        for &a in &touched {
            rows[a as usize].extend(&touched);
        }
    }
    for (k, row) in q.outer_iterator().enumerate() {
        let mut bs: Vec<u32> = row
            .indices()
            .iter()
            .flat_map(|&l| aggs_of(l as u32))
            .collect();
        bs.sort_unstable();
        bs.dedup();
        for a in aggs_of(k as u32) {
            rows[a as usize].extend(&bs);
        }
    }
    for row in &mut rows {
        row.sort_unstable();
        row.dedup();
    }
    rows
}

/// Fills each block `(a, b)`, `b < a`, of `G` with the transpose of the
/// block `(b, a)`: the tasks sum the blocks on and above the diagonal
/// only, `G` being symmetric.
fn mirror_lower(space: &RigidSpace, g: &mut sprs::CsMat<Real>) {
    let data = g.data_mut();
    // block (a, c-th of row a) starts at 36 ptr[a] + 6 c, its rows 6 n apart
    for a in 0..space.len() {
        let cols = &space.cols[space.ptr[a]..space.ptr[a + 1]];
        let n = cols.len();
        for (c, &b) in cols.iter().enumerate() {
            let b = b as usize;
            if b >= a {
                break;
            }
            let bcols = &space.cols[space.ptr[b]..space.ptr[b + 1]];
            let nb = bcols.len();
            let cb = bcols
                .binary_search(&(a as u32))
                .expect("a symmetric pattern");
            for i in 0..6 {
                for j in 0..6 {
                    data[36 * space.ptr[a] + i * 6 * n + 6 * c + j] =
                        data[36 * space.ptr[b] + j * 6 * nb + 6 * cb + i];
                }
            }
        }
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
    /// `Q' = Q − Σ_t w_t A_tᵀ A_t` on the unknowns (module docs): `q`
    /// (`Q_UU`, whose pattern holds every triangle's pairs of unknown
    /// corners) less each area triangle's `w Σ_d κ_d κ_dᵀ`.
    pub(crate) fn without_area(&self, els: &Elements, q: &sprs::CsMat<Real>) -> sprs::CsMat<Real> {
        let mut out = q.to_csr();
        for t in 0..self.area.len() {
            let (_, unknown) = els.support(els.num_vertices() + t);
            let el = &self.area[t];
            let k = el.corners();
            for (c, &u) in unknown.iter().enumerate() {
                for (c2, &u2) in unknown.iter().enumerate() {
                    if u == u32::MAX || u2 == u32::MAX {
                        continue;
                    }
                    let v = el.weight * (k[c][0] * k[c2][0] + k[c][1] * k[c2][1]);
                    *out.get_mut(u as usize, u2 as usize)
                        .expect("a triangle's corners in Q's pattern") -= v;
                }
            }
        }
        out
    }

    /// Writes `G = Pᵀ H P` (module docs) into `g`'s values
    /// ([`RigidSpace::pattern`]), `H` with `curvature`, at the normalised
    /// pose `y`, rotations `rot` and area targets `proj`, with each
    /// entry's lever arm `r_ka` in `lever` and `Q'` in `q`
    /// ([`ElasticOps::without_area`]); on the rayon pool, a group of
    /// aggregates per task.
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
        // the groups' disjoint value slices
        let groups = space.gptr.len() - 1;
        let mut tasks = Vec::with_capacity(groups);
        let mut rest = g.data_mut();
        for gr in 0..groups {
            let (a0, a1) = (space.gptr[gr], space.gptr[gr + 1]);
            let len = 36 * (space.ptr[a1] - space.ptr[a0]);
            let (row, tail) = rest.split_at_mut(len);
            tasks.push((gr, row));
            rest = tail;
        }
        tasks.into_par_iter().for_each_init(
            || -> Scratch { Default::default() },
            |(blocks, j, parts, modes), (gr, out)| {
                let (a0, a1) = (space.gptr[gr], space.gptr[gr + 1]);
                // the group's blocks, rows in order (row a's from
                // `ptr[a] − ptr[a0]`)
                let base = space.ptr[a0];
                blocks.clear();
                blocks.resize(space.ptr[a1] - base, M6::zeros());
                let at = |a: u32, b: u32| {
                    let cols = &space.cols[space.ptr[a as usize]..space.ptr[a as usize + 1]];
                    space.ptr[a as usize] - base
                        + cols.binary_search(&b).expect("a block of the pattern")
                };
                for a in a0..a1 {
                    self.q_rows(space, a, q, lever, &at, blocks);
                }
                let rows = (a0 as u32)..(a1 as u32);
                for &e in &space.gelems[space.geptr[gr]..space.geptr[gr + 1]] {
                    self.element_rows(
                        space,
                        els,
                        ops,
                        e as usize,
                        &rows,
                        (y, rot, proj),
                        lever,
                        curvature,
                        (&at, j, parts, modes),
                        blocks,
                    );
                }
                // rows of six scalar rows, each with six columns per block
                for a in a0..a1 {
                    let (s, e) = (space.ptr[a] - base, space.ptr[a + 1] - base);
                    let n = e - s;
                    let row_out = &mut out[36 * s..36 * e];
                    for (c, blk) in blocks[s..e].iter().enumerate() {
                        for i in 0..6 {
                            for jj in 0..6 {
                                row_out[i * 6 * n + 6 * c + jj] = blk[(i, jj)];
                            }
                        }
                    }
                }
            },
        );
        mirror_lower(space, g);
    }

    /// Adds the rows of `Q'` of aggregate `a`'s entries (module docs), to
    /// the blocks on and above the diagonal.
    ///
    /// Per block `(a, b)`, with `s`, `v` of each entry `k` of `a` weighted
    /// by `w_ka`: `[[S I, −[V]×], [[R]×, −Σ w_ka [r_ka]×[v]×]]`, `S = Σ w s`,
    /// `V = Σ w v`, `R = Σ w s r_ka`, and `[r]×[v]× = v rᵀ − (r·v) I`.
    fn q_rows(
        &self,
        space: &RigidSpace,
        a: usize,
        q: &sprs::CsMat<Real>,
        lever: &[Vector3<Real>],
        at: &dyn Fn(u32, u32) -> usize,
        blocks: &mut [M6],
    ) {
        /// `(S, V, R, Σ w v rᵀ, Σ w r·v)` of a block.
        type Sums = (Real, Vector3<Real>, Vector3<Real>, Matrix3<Real>, Real);
        let wts = &space.weights;
        let mut acc: Vec<(u32, (Real, Vector3<Real>))> = Vec::new();
        let mut sums: Vec<(u32, Sums)> = Vec::new();
        for &ea in space.members(a) {
            let ea = ea as usize;
            let k = space.entry_unknown[ea] as usize;
            let (wk, rk) = (wts.w[ea], lever[ea]);
            acc.clear();
            let row = q.outer_view(k).expect("a row of Q'");
            for (l, &v) in row.iter() {
                for f in wts.entries(l) {
                    let b = wts.agg[f];
                    if (b as usize) < a {
                        continue;
                    }
                    let s = v * wts.w[f];
                    let i = slot(&mut acc, b, (0.0, Vector3::zeros()));
                    let x = &mut acc[i].1;
                    x.0 += s;
                    x.1 += s * lever[f];
                }
            }
            for &(b, (s, v)) in &acc {
                let (ws, wv) = (wk * s, wk * v);
                let zero = (
                    0.0,
                    Vector3::zeros(),
                    Vector3::zeros(),
                    Matrix3::zeros(),
                    0.0,
                );
                let i = slot(&mut sums, b, zero);
                let x = &mut sums[i].1;
                x.0 += ws;
                x.1 += wv;
                x.2 += ws * rk;
                x.3 += wv * rk.transpose();
                x.4 += rk.dot(&wv);
            }
        }
        for &(b, (s, v, r, vr, rv)) in &sums {
            let blk = &mut blocks[at(a as u32, b)];
            for i in 0..3 {
                blk[(i, i)] += s;
            }
            let mut tr = blk.fixed_view_mut::<3, 3>(0, 3);
            tr -= cross_matrix(&v);
            let mut bl = blk.fixed_view_mut::<3, 3>(3, 0);
            bl += cross_matrix(&r);
            // −Σ w [r]×[v]× = −Σ w v rᵀ + Σ w (r·v) I
            let mut br = blk.fixed_view_mut::<3, 3>(3, 3);
            br -= vr;
            for i in 0..3 {
                br[(i, i)] += rv;
            }
        }
    }

    /// Adds element `e`'s blocks of the block rows in `rows` (module docs).
    #[allow(clippy::too_many_arguments)]
    fn element_rows(
        &self,
        space: &RigidSpace,
        els: &Elements,
        ops: &Operators,
        e: usize,
        rows: &std::ops::Range<u32>,
        (y, rot, proj): (&[Point], &[UnitQuaternion<Real>], &[[Real; 6]]),
        lever: &[Vector3<Real>],
        curvature: Curvature,
        (at, j, parts, modes): ElementScratch,
        blocks: &mut [M6],
    ) {
        let wts = &space.weights;
        let (support, unknown) = els.support(e);
        if let Some(i) = els.vertex(e) {
            let (c_inv, _) = self.vertex_coupling(ops, i, support, (y, &rot[i]), curvature, j);
            let Some(c_inv) = c_inv else { return };
            // (J P)_b = Σ_k J_k w_kb [I | −[r_kb]×]
            parts.clear();
            for (s, &k) in unknown.iter().enumerate() {
                if k == u32::MAX {
                    continue;
                }
                for f in wts.entries(k as usize) {
                    let wj = j[s] * wts.w[f];
                    let p = slot(parts, wts.agg[f], M36::zeros());
                    let m = &mut parts[p].1;
                    let mut left = m.fixed_view_mut::<3, 3>(0, 0);
                    left += wj;
                    let mut right = m.fixed_view_mut::<3, 3>(0, 3);
                    right -= wj * cross_matrix(&lever[f]);
                }
            }
            // −(C⁻¹ (J P)_a)ᵀ (J P)_b for the rows a of this task, b ≥ a
            for (a, ua) in parts.iter() {
                if !rows.contains(a) {
                    continue;
                }
                let l = (c_inv * ua).transpose();
                for (b, ub) in parts.iter() {
                    if b >= a {
                        blocks[at(*a, *b)] -= l * ub;
                    }
                }
            }
        } else {
            let t = e - els.num_vertices();
            let el = &self.area[t];
            triangle_modes(el, y, &proj[t], curvature, |wl, am| {
                // Pᵀ Aᵀ m per aggregate: w_kb [a; r_kb × a], a = (Aᵀ m)_k
                modes.clear();
                for (c, &u) in unknown.iter().enumerate() {
                    if u == u32::MAX {
                        continue;
                    }
                    for f in wts.entries(u as usize) {
                        let a = am[c] * wts.w[f];
                        let m = lever[f].cross(&a);
                        let v = V6::new(a.x, a.y, a.z, m.x, m.y, m.z);
                        let p = slot(modes, wts.agg[f], V6::zeros());
                        modes[p].1 += v;
                    }
                }
                for (a, va) in modes.iter() {
                    if !rows.contains(a) {
                        continue;
                    }
                    let left = wl * va;
                    for (b, vb) in modes.iter() {
                        if b >= a {
                            blocks[at(*a, *b)] += left * vb.transpose();
                        }
                    }
                }
            });
        }
    }
}
