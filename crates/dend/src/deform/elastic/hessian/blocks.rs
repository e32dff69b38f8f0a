//! The Newton matrix's element blocks (module docs of `hessian`): the
//! elements and their supports in a fixed order ([`Elements`], once per
//! constraint set), and each element's 3×3 blocks at a pose
//! ([`ElasticOps::coupling_blocks`]), computed in parallel into one buffer
//! that the Newton iteration sums into its pattern.
//!
//! Element `e`'s blocks are those of the pairs `(a, b)`, `a ≤ b`, of the
//! unknowns of its support (in the support's order): the block of unknowns
//! `(k_a, k_b)`; the block of `(k_b, k_a)` is its transpose. Writing each
//! pair once halves the Schur complements' products and makes the
//! assembled matrix exactly symmetric. Every element writes all its
//! blocks (zeros where `C` is singular), so where they go depends on the
//! constraint set only.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::{
    area_eigensystem, area_normal, cross_matrix, cut, gram, positive_part, rotation_curvature,
    semi_definite, AreaMode, Curvature,
};
use crate::deform::elastic::area::{gradient, AreaElement};
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::mesh::{Point, Real};
use crate::operators::Operators;

/// Elements per task of [`ElasticOps::coupling_blocks`]: a few
/// microseconds of work each, so that the pool's scheduling costs little.
const CHUNK: usize = 128;

/// The elements of the Newton matrix for one constraint set: each fitted
/// free vertex (its spokes' ends and its Laplacian row), then each area
/// triangle, with their supports and where their blocks start in the
/// buffer of [`ElasticOps::coupling_blocks`].
#[derive(Debug, Clone)]
pub(crate) struct Elements {
    /// The fitted free vertices, ascending: element `e < vertices.len()`
    /// is vertex `vertices[e]`, element `vertices.len() + t` area triangle
    /// `t`.
    vertices: Vec<u32>,
    /// Each element's support (CSR): a vertex's sorted and deduplicated,
    /// a triangle's corners in order.
    ptr: Vec<usize>,
    support: Vec<u32>,
    /// Each support entry's unknown, `u32::MAX` for a constrained vertex.
    unknown: Vec<u32>,
    /// Each element's first block (and the total at the end).
    first: Vec<usize>,
}

impl Elements {
    /// How many elements there are.
    pub(crate) fn len(&self) -> usize {
        self.ptr.len() - 1
    }

    /// How many blocks all elements write.
    pub(crate) fn num_blocks(&self) -> usize {
        self.first[self.len()]
    }

    /// Element `e`'s support and each entry's unknown (`u32::MAX` for a
    /// constrained vertex).
    pub(crate) fn support(&self, e: usize) -> (&[u32], &[u32]) {
        let r = self.ptr[e]..self.ptr[e + 1];
        (&self.support[r.clone()], &self.unknown[r])
    }

    /// The vertex of element `e`, `None` for an area triangle (element
    /// `num_vertices() + t` is triangle `t`).
    pub(crate) fn vertex(&self, e: usize) -> Option<usize> {
        self.vertices.get(e).map(|&v| v as usize)
    }

    /// How many of the elements are vertices.
    pub(crate) fn num_vertices(&self) -> usize {
        self.vertices.len()
    }

    /// The unknowns of element `e`'s support, in its blocks' order.
    pub(crate) fn unknowns(&self, e: usize) -> impl Iterator<Item = u32> + '_ {
        self.unknown[self.ptr[e]..self.ptr[e + 1]]
            .iter()
            .copied()
            .filter(|&k| k != u32::MAX)
    }

    /// Calls `f(k, l, index, pair)` for each block of each element, in the
    /// buffer's order: the block of unknowns `(k, l)` at `index`, and
    /// whether it is of two support entries `a < b` (`pair`: its transpose
    /// is also the block of `(l, k)`) or of one (`a = b`).
    pub(crate) fn for_each_block(&self, mut f: impl FnMut(u32, u32, usize, bool)) {
        let mut index = 0;
        let mut unknowns = Vec::new();
        for e in 0..self.len() {
            unknowns.clear();
            unknowns.extend(self.unknowns(e));
            for (a, &k) in unknowns.iter().enumerate() {
                for (b, &l) in unknowns.iter().enumerate().skip(a) {
                    f(k, l, index, b > a);
                    index += 1;
                }
            }
            debug_assert_eq!(index, self.first[e + 1]);
        }
    }
}

impl ElasticOps {
    /// The elements of the Newton matrix for `set`, with the unknowns of
    /// `col_of` (vertex → unknown, `u32::MAX` for none).
    pub(crate) fn coupling_elements(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        col_of: &[u32],
    ) -> Elements {
        let vertices: Vec<u32> = (0..set.free.len())
            .filter(|&i| set.free[i] && set.fit[i])
            .map(|i| i as u32)
            .collect();
        let mut ptr = vec![0];
        let mut support = Vec::new();
        for &i in &vertices {
            let i = i as usize;
            let start = support.len();
            support.push(i as u32);
            support.extend(&self.nbr[self.ptr[i]..self.ptr[i + 1]]);
            if self.b[i] > 0.0 {
                let row = ops.lbar.outer_view(i).expect("row of a vertex");
                support.extend(row.indices().iter().map(|&k| k as u32));
            }
            support[start..].sort_unstable();
            let mut kept = start;
            for s in start..support.len() {
                if s == start || support[s] != support[kept - 1] {
                    support[kept] = support[s];
                    kept += 1;
                }
            }
            support.truncate(kept);
            ptr.push(support.len());
        }
        for el in &self.area {
            support.extend(&el.v);
            ptr.push(support.len());
        }
        let unknown: Vec<u32> = support.iter().map(|&v| col_of[v as usize]).collect();
        let mut first = vec![0];
        for e in 0..ptr.len() - 1 {
            let m = unknown[ptr[e]..ptr[e + 1]]
                .iter()
                .filter(|&&k| k != u32::MAX)
                .count();
            first.push(first[e] + m * (m + 1) / 2);
        }
        Elements {
            vertices,
            ptr,
            support,
            unknown,
            first,
        }
    }

    /// Each element's blocks (module docs) of `−Jᵀ C⁻¹ J` per fitted free
    /// vertex, `w ((Aᵀn)(Aᵀn)ᵀ − AᵀA)` per triangle (`Q` holds `w AᵀA`),
    /// with the elements' `curvature`, at the normalised pose `y`, the
    /// rotations `rot` and area targets `proj`, written into `blocks`
    /// ([`Elements::num_blocks`] long) on the rayon pool. `indefinite[e]`
    /// is set to whether element `e`'s curvature has a negative
    /// eigenvalue (its blocks differ between the curvatures). With
    /// `only_indefinite`, only the elements marked so are computed again
    /// (the others' blocks are the same for both curvatures).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn coupling_blocks(
        &self,
        els: &Elements,
        ops: &Operators,
        (y, rot, proj): (&[Point], &[UnitQuaternion<Real>], &[[Real; 6]]),
        curvature: Curvature,
        blocks: &mut [Matrix3<Real>],
        indefinite: &mut [bool],
        only_indefinite: bool,
    ) {
        assert_eq!(blocks.len(), els.num_blocks());
        assert_eq!(indefinite.len(), els.len());
        // disjoint slices of the elements' chunks
        let mut tasks = Vec::with_capacity(els.len().div_ceil(CHUNK));
        let (mut rest_b, mut rest_f) = (blocks, indefinite);
        for start in (0..els.len()).step_by(CHUNK) {
            let end = (start + CHUNK).min(els.len());
            let (b, tail_b) = rest_b.split_at_mut(els.first[end] - els.first[start]);
            let (f, tail_f) = rest_f.split_at_mut(end - start);
            tasks.push((start, b, f));
            (rest_b, rest_f) = (tail_b, tail_f);
        }
        let nv = els.vertices.len();
        tasks
            .into_par_iter()
            .for_each_init(Vec::new, |j, (start, b, f)| {
                let base = els.first[start];
                for (o, flag) in f.iter_mut().enumerate() {
                    let e = start + o;
                    if only_indefinite && !*flag {
                        continue;
                    }
                    let out = &mut b[els.first[e] - base..els.first[e + 1] - base];
                    let (support, unknown) = (
                        &els.support[els.ptr[e]..els.ptr[e + 1]],
                        &els.unknown[els.ptr[e]..els.ptr[e + 1]],
                    );
                    *flag = if e < nv {
                        let i = els.vertices[e] as usize;
                        let k = (support, unknown);
                        self.vertex_blocks(ops, i, k, (y, &rot[i]), curvature, j, out)
                    } else {
                        let el = &self.area[e - nv];
                        triangle_blocks(el, unknown, y, &proj[e - nv], curvature, out)
                    };
                }
            });
    }

    /// Vertex `i`'s blocks `−J_aᵀ C⁻¹ J_b` (zeros where `C` is singular)
    /// over its `support` with its `unknown`s; whether its curvature is
    /// indefinite. `j` is scratch.
    #[allow(clippy::too_many_arguments)]
    fn vertex_blocks(
        &self,
        ops: &Operators,
        i: usize,
        (support, unknown): (&[u32], &[u32]),
        (y, q): (&[Point], &UnitQuaternion<Real>),
        curvature: Curvature,
        j: &mut Vec<Matrix3<Real>>,
        out: &mut [Matrix3<Real>],
    ) -> bool {
        let (c_inv, indefinite) = self.vertex_coupling(ops, i, support, (y, q), curvature, j);
        let Some(c_inv) = c_inv else {
            out.fill(Matrix3::zeros());
            return indefinite;
        };
        let mut o = 0;
        for a in 0..support.len() {
            if unknown[a] == u32::MAX {
                continue;
            }
            let left = j[a].transpose() * c_inv;
            for b in a..support.len() {
                if unknown[b] != u32::MAX {
                    out[o] = -(left * j[b]);
                    o += 1;
                }
            }
        }
        indefinite
    }

    /// Vertex `i`'s `J` (one 3×3 block per entry of its sorted `support`,
    /// into `j`) and `C⁻¹` (`None` where `C` is singular), with the
    /// `curvature` of its rotation (module docs of `hessian`); whether that
    /// curvature is indefinite.
    pub(crate) fn vertex_coupling(
        &self,
        ops: &Operators,
        i: usize,
        support: &[u32],
        (y, q): (&[Point], &UnitQuaternion<Real>),
        curvature: Curvature,
        j: &mut Vec<Matrix3<Real>>,
    ) -> (Option<Matrix3<Real>>, bool) {
        let at = |v: usize| {
            support
                .binary_search(&(v as u32))
                .expect("a vertex of the element's support")
        };
        let r = q.to_rotation_matrix();
        let yi = Vector3::from(y[i]);
        let me = at(i);
        j.clear();
        j.resize(support.len(), Matrix3::zeros());
        let mut c = Matrix3::zeros();
        let mut bend = Matrix3::zeros();
        for s in self.ptr[i]..self.ptr[i + 1] {
            let t = r * Vector3::from(self.e[s]);
            let nb = self.nbr[s] as usize;
            let rho = Vector3::from(y[nb]) - yi - t;
            c += self.c[s] * gram(&t);
            bend += self.c[s] * rotation_curvature(&rho, &t);
            // ρ = (y_j − y_i) − R_i e_ij: A dY = dy_j − dy_i
            let k = self.c[s] * cross_matrix(&t).transpose();
            j[at(nb)] += k;
            j[me] -= k;
        }
        if self.b[i] > 0.0 {
            // ρ = (L Y)_i − R_i δ_i: A dY = Σ_k L_ik dy_k, L = D⁻¹ Lbar
            let t = r * Vector3::from(ops.delta[i]);
            let kt = self.b[i] * cross_matrix(&t).transpose();
            let row = ops.lbar.outer_view(i).expect("row of a vertex");
            let mut ly = Vector3::zeros();
            for (k, &w) in row.iter() {
                let l = w / ops.area[i];
                ly += l * Vector3::from(y[k]);
                j[at(k)] += l * kt;
            }
            c += self.b[i] * gram(&t);
            bend += self.b[i] * rotation_curvature(&(ly - t), &t);
        }
        if curvature == Curvature::GaussNewton {
            return (c.try_inverse(), false);
        }
        let indefinite = !semi_definite(&bend);
        c += match curvature {
            Curvature::Projected if indefinite => positive_part(&bend),
            _ => bend,
        };
        (c.try_inverse(), indefinite)
    }
}

/// Triangle `el`'s blocks `w ((Aᵀn)(Aᵀn)ᵀ − AᵀA)` over its corners with
/// their `unknown`s, at the pose `y` (its area target `p` where the
/// eigensystem is ill-conditioned); whether its curvature is indefinite.
fn triangle_blocks(
    el: &AreaElement,
    unknown: &[u32],
    y: &[Point],
    p: &[Real; 6],
    curvature: Curvature,
    out: &mut [Matrix3<Real>],
) -> bool {
    let k = el.corners();
    let w = el.weight;
    let pairs = || {
        (0..3).filter(|&a| unknown[a] != u32::MAX).flat_map(|a| {
            (a..3)
                .filter(|&b| unknown[b] != u32::MAX)
                .map(move |b| (a, b))
        })
    };
    // `Q` holds w AᵀA: take it out, then add w Aᵀ (½ ∇²_F) A
    for ((a, b), o) in pairs().zip(out.iter_mut()) {
        let kk = k[a][0] * k[b][0] + k[a][1] * k[b][1];
        *o = Matrix3::identity() * (-w * kk);
    }
    triangle_modes(el, y, p, curvature, |wl, am| {
        for ((a, b), o) in pairs().zip(out.iter_mut()) {
            *o += wl * am[a] * am[b].transpose();
        }
    })
}

/// Triangle `el`'s curvature modes at the pose `y` (its area target `p`
/// where the eigensystem is ill-conditioned), each as `f(w λ, Aᵀ m)`
/// with its eigenvalue kept by `curvature` (zero ones skipped) and `Aᵀ m`
/// per corner: the area term's part of the Newton matrix beyond `Q`'s
/// `w AᵀA` is `Σ w λ (Aᵀm)(Aᵀm)ᵀ − w AᵀA`. Returns whether the curvature
/// is indefinite.
pub(super) fn triangle_modes(
    el: &AreaElement,
    y: &[Point],
    p: &[Real; 6],
    curvature: Curvature,
    mut f: impl FnMut(Real, [Vector3<Real>; 3]),
) -> bool {
    let k = el.corners();
    let w = el.weight;
    let modes = match curvature {
        Curvature::GaussNewton => None,
        _ => area_eigensystem(&gradient(y, el)),
    };
    let gauss_newton;
    let (modes, indefinite): (&[AreaMode], bool) = match &modes {
        Some(m) => (m, m.iter().any(|&(l, _)| cut(l))),
        None => match area_normal(p) {
            Some(n) => {
                gauss_newton = [(1.0, n)];
                (&gauss_newton, false)
            }
            None => (&[], false),
        },
    };
    for &(lambda, [m0, m1]) in modes {
        let lambda = curvature.keep(lambda);
        if lambda == 0.0 {
            continue;
        }
        // (Aᵀ m)_v = k_v0 m_0 + k_v1 m_1
        let am = k.map(|kv| kv[0] * m0 + kv[1] * m1);
        f(w * lambda, am);
    }
    indefinite
}

/// Calls `add(k, l, B)` with every block of the matrix the elements' blocks
/// make (both triangles; duplicates to be summed), elements in order: the
/// plain scatter the planned assembly is tested against.
#[cfg(test)]
pub(crate) fn each_block(
    els: &Elements,
    blocks: &[Matrix3<Real>],
    mut add: impl FnMut(u32, u32, &Matrix3<Real>),
) {
    els.for_each_block(|k, l, index, pair| {
        add(k, l, &blocks[index]);
        if pair {
            add(l, k, &blocks[index].transpose());
        }
    });
}
