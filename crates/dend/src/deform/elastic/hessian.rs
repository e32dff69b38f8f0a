//! The Gauss–Newton Hessian of the elastic energy with its rotations
//! eliminated: the matrix of the coarsest level's Newton step
//! (`solver/newton.rs`).
//!
//! Every rotation-dependent term of `E(Y, R, P)` belongs to one element:
//! a free vertex `i` (its spokes and its Laplacian row, rotation `R_i`) or
//! a triangle `t` (its area target `P_t`, turned by a rotation of its
//! own). Turning an element's rotation by a small world-frame vector `ω`,
//! `R ← (I + [ω]×) R`, each of its residuals `ρ` changes as
//!
//! ```text
//! ρ(Y + dY, ω) ≈ ρ + A dY + [t]× ω        (t: the rotated rest vector: R_i e_ij, R_i δ_i, a column of P_t)
//! ```
//!
//! so the element's energy is, to second order in `(dY, ω)`, the sum of
//! squares `Σ w |ρ + A dY + [t]× ω|²`: positive semi-definite in both.
//! Minimising it over `ω` (a 3×3 solve per element) leaves the Schur
//! complement
//!
//! ```text
//! H_e = Σ w AᵀA − J_eᵀ C_e⁻¹ J_e,   C_e = Σ w (|t|² I − t tᵀ),   J_e = Σ w [t]×ᵀ A
//! ```
//!
//! which is positive semi-definite too. `Σ_e Σ w AᵀA` is the global
//! step's `Q` (the same elements, rotations held), so the Gauss–Newton
//! matrix of the energy reduced over the rotations is
//! `Q ⊗ I₃ − Σ_e J_eᵀ C_e⁻¹ J_e`: the global step's matrix, less the
//! stiffness the held rotations add. That stiffness is what makes a far
//! part swinging as a whole converge slowly under the local/global
//! iteration (the rotations lag the pose by a share of the swing at every
//! iteration); the Gauss–Newton step turns the part and its rotations
//! together. This is the Gauss–Newton reading of ARAP with its rotations
//! as unknowns (Sorkine & Alexa 2007's energy; the elimination of the
//! per-element rotation is the static condensation of a mixed finite
//! element). The area targets' stretch `diag(d, 1/d)` is held as
//! Gauss–Newton holds second derivatives of the residuals.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::{ElasticOps, ElasticSet};
use crate::mesh::Real;
use crate::operators::Operators;

/// `[t]×`, the cross-product matrix: `[t]× v = t × v`.
fn cross_matrix(t: &Vector3<Real>) -> Matrix3<Real> {
    Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0)
}

/// `|t|² I − t tᵀ = [t]×ᵀ [t]×`.
fn gram(t: &Vector3<Real>) -> Matrix3<Real> {
    Matrix3::identity() * t.norm_squared() - t * t.transpose()
}

/// Adds `−Σ_k,l J_kᵀ C⁻¹ J_l` through `add` for the blocks `J` of one
/// element (vertex, 3×3 block), in unknown numbering `col_of` (`add(k, l,
/// B)` adds the 3×3 block `B` at unknowns `(k, l)`); blocks of vertices
/// that are not unknowns are skipped. Nothing when `C` is singular.
fn add_schur(
    c: &Matrix3<Real>,
    blocks: &[(u32, Matrix3<Real>)],
    col_of: &[u32],
    add: &mut impl FnMut(u32, u32, &Matrix3<Real>),
) {
    let Some(c_inv) = c.try_inverse() else {
        return;
    };
    for &(k, jk) in blocks {
        let ck = col_of[k as usize];
        if ck == u32::MAX {
            continue;
        }
        let left = jk.transpose() * c_inv;
        for &(l, jl) in blocks {
            let cl = col_of[l as usize];
            if cl == u32::MAX {
                continue;
            }
            add(ck, cl, &-(left * jl));
        }
    }
}

impl ElasticOps {
    /// Adds the rotation coupling `−Σ_e J_eᵀ C_e⁻¹ J_e` (module docs) at
    /// the rotations `rot` and area targets `proj` through `add(k, l, B)`,
    /// the 3×3 block `B` of unknowns `(k, l)` in `col_of`'s numbering
    /// (vertex → unknown, `u32::MAX` for none). Both triangles of the
    /// symmetric matrix are added, duplicates to be summed. The blocks
    /// added are among [`ElasticOps::coupling_supports`]' pairs.
    pub(crate) fn rotation_coupling(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        rot: &[UnitQuaternion<Real>],
        proj: &[[Real; 6]],
        col_of: &[u32],
        mut add: impl FnMut(u32, u32, &Matrix3<Real>),
    ) {
        let mut blocks: Vec<(u32, Matrix3<Real>)> = Vec::new();
        for (i, q) in rot.iter().enumerate().take(set.free.len()) {
            if !(set.free[i] && set.fit[i]) {
                continue;
            }
            let r = q.to_rotation_matrix();
            let mut c = Matrix3::zeros();
            blocks.clear();
            blocks.push((i as u32, Matrix3::zeros()));
            for s in self.ptr[i]..self.ptr[i + 1] {
                let t = r * Vector3::from(self.e[s]);
                c += self.c[s] * gram(&t);
                // ρ = (y_j − y_i) − R_i e_ij: A dY = dy_j − dy_i
                let k = self.c[s] * cross_matrix(&t).transpose();
                blocks.push((self.nbr[s], k));
                blocks[0].1 -= k;
            }
            if self.b[i] > 0.0 {
                // ρ = (L Y)_i − R_i δ_i: A dY = Σ_k L_ik dy_k, L = D⁻¹ Lbar
                let t = r * Vector3::from(ops.delta[i]);
                c += self.b[i] * gram(&t);
                let kt = self.b[i] * cross_matrix(&t).transpose();
                let row = ops.lbar.outer_view(i).expect("row of a vertex");
                for (k, &w) in row.iter() {
                    let l = w / ops.area[i];
                    match blocks.iter_mut().find(|(v, _)| *v as usize == k) {
                        Some(b) => b.1 += l * kt,
                        None => blocks.push((k as u32, l * kt)),
                    }
                }
            }
            add_schur(&c, &blocks, col_of, &mut add);
        }
        for (el, p) in self.area.iter().zip(proj) {
            // ρ_c = F_c(Y) − p_c, F = [e1 e2] B: column c of F is
            // e1 B_0c + e2 B_1c with e1 = y1 − y0, e2 = y2 − y0
            let cols = [
                Vector3::new(p[0], p[1], p[2]),
                Vector3::new(p[3], p[4], p[5]),
            ];
            let w = el.weight;
            let mut c = Matrix3::zeros();
            let mut j = [Matrix3::zeros(); 3];
            for (col, t) in cols.iter().enumerate() {
                c += w * gram(t);
                let kt = w * cross_matrix(t).transpose();
                let (b1, b2) = (el.b[(0, col)], el.b[(1, col)]);
                j[1] += b1 * kt;
                j[2] += b2 * kt;
                j[0] -= (b1 + b2) * kt;
            }
            blocks.clear();
            blocks.extend(el.v.iter().zip(j).map(|(&v, m)| (v, m)));
            add_schur(&c, &blocks, col_of, &mut add);
        }
    }

    /// Calls `f` with the vertices of each element that
    /// [`ElasticOps::rotation_coupling`] visits (a fitted free vertex with
    /// its spokes' ends and its Laplacian row, a triangle with an area
    /// term): every pair of unknowns among one element's vertices may get
    /// a block, whatever the rotations. The pattern of the Newton matrix.
    pub(crate) fn coupling_supports(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        mut f: impl FnMut(&[u32]),
    ) {
        let mut support: Vec<u32> = Vec::new();
        for i in 0..set.free.len() {
            if !(set.free[i] && set.fit[i]) {
                continue;
            }
            support.clear();
            support.push(i as u32);
            support.extend(&self.nbr[self.ptr[i]..self.ptr[i + 1]]);
            if self.b[i] > 0.0 {
                let row = ops.lbar.outer_view(i).expect("row of a vertex");
                support.extend(row.indices().iter().map(|&k| k as u32));
            }
            support.sort_unstable();
            support.dedup();
            f(&support);
        }
        for el in &self.area {
            f(&el.v);
        }
    }
}
