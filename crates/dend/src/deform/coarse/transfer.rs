//! Transfers between the levels for the coarse corrections (full
//! approximation scheme in rotation space, `solver/multilevel.rs`): fine forces
//! restricted to the coarse vertices, coarse rotation vectors prolongated
//! to the fine ones.
//!
//! Both use the *smoothed aggregation* prolongation `P = Sᵏ P₀`
//! (Vaněk, Mandel & Brezina 1996): `P₀` gives each fine vertex its nearest
//! coarse vertex's value (`CoarseLevel::near`) and `S = D⁻¹(A + I)`
//! averages over the closed 1-ring (`A` the fine adjacency, `D` the closed
//! degrees). Rows of fine constrained vertices and columns of coarse
//! constrained ones are zero: neither level moves its constrained vertices.
//! Plain aggregation (`k = 0`) is piecewise constant: its restriction
//! weights each fine force by one coarse cell only, and its prolongated
//! rotations jump between cells, a high-frequency error that raised the
//! camel's fine energy in the prototype (FINDINGS2, 23:08).

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::deform::rest::{CoarseLevel, Rest};
use crate::mesh::{Point, Real};

/// Smoothing passes of the restriction `Pᵀ` (prototype: 3).
pub const RESTRICTION_PASSES: usize = 3;

/// Smoothing passes of the rotation-vector prolongation (prototype: 10;
/// 10 and 20 both turned the camel's rejected correction into a descent).
pub const PROLONGATION_PASSES: usize = 10;

/// The fewest fine vertices whose smoothing passes run on the rayon pool:
/// a correction's transfers are passes over the whole fine mesh, on the
/// calling thread they cost a fifth to a third of a fine iteration.
pub(crate) const PARALLEL_MIN: usize = 2048;

/// Vertices per task of a parallel smoothing pass.
const CHUNK: usize = 512;

/// `out_i = f(i)` for every vertex: on the rayon pool from
/// [`PARALLEL_MIN`] vertices (each value on its own, so the result does
/// not depend on how the work is split).
fn each_vertex(out: &mut [Vector3<Real>], f: impl Fn(usize) -> Vector3<Real> + Sync) {
    if out.len() >= PARALLEL_MIN {
        out.par_iter_mut()
            .enumerate()
            .with_min_len(CHUNK)
            .for_each(|(i, o)| *o = f(i));
    } else {
        for (i, o) in out.iter_mut().enumerate() {
            *o = f(i);
        }
    }
}

impl CoarseLevel {
    /// `r = Pᵀ f` with `P = (Sᵏ P₀)` masked (module docs), `k = passes`
    /// ([`RESTRICTION_PASSES`] for the corrections): the fine forces `f` (`#V`, zero where
    /// `fine_fixed`) summed onto the coarse vertices (`#Vc`, zero where
    /// `coarse_fixed`). With `Sᵀ = (A + I) D⁻¹`, `(Sᵀ v)_i = v_i/d_i +
    /// Σ_{j ∈ N(i)} v_j/d_j`.
    pub fn restrict_forces(
        &self,
        fine: &Rest,
        f: &[Point],
        fine_fixed: &[bool],
        coarse_fixed: &[bool],
        passes: usize,
    ) -> Vec<Point> {
        let topo = fine.mesh.topology();
        let n = f.len();
        let closed_degree = |i: usize| (topo.ring(i).len() + 1) as Real;
        let mut v: Vec<Vector3<Real>> = (0..n)
            .map(|i| {
                if fine_fixed[i] {
                    Vector3::zeros()
                } else {
                    Vector3::from(f[i])
                }
            })
            .collect();
        let mut next = vec![Vector3::zeros(); n];
        for _ in 0..passes {
            // each `v_j / d_j` once, summed in the same order as before
            for (i, vi) in v.iter_mut().enumerate() {
                *vi /= closed_degree(i);
            }
            each_vertex(&mut next, |i| {
                let mut acc = v[i];
                for &j in topo.ring(i) {
                    acc += v[j as usize];
                }
                acc
            });
            std::mem::swap(&mut v, &mut next);
        }
        let mut r = vec![[0.0; 3]; self.num_vertices()];
        for (i, vi) in v.iter().enumerate() {
            let c = self.near[i];
            if c != u32::MAX && !coarse_fixed[c as usize] {
                let o = &mut r[c as usize];
                o[0] += vi[0];
                o[1] += vi[1];
                o[2] += vi[2];
            }
        }
        r
    }

    /// `w = P w_c` with `P = (Sᵏ P₀)` masked (module docs), `k = passes`
    /// ([`PROLONGATION_PASSES`] for the corrections): coarse vectors (`#Vc`; values at
    /// `coarse_fixed` vertices are ignored) as a smooth field over the fine
    /// vertices (`#V`, zero where `fine_fixed`).
    pub fn prolongate_vectors(
        &self,
        fine: &Rest,
        wc: &[Vector3<Real>],
        fine_fixed: &[bool],
        coarse_fixed: &[bool],
        passes: usize,
    ) -> Vec<Vector3<Real>> {
        let topo = fine.mesh.topology();
        let n = self.near.len();
        let mut v: Vec<Vector3<Real>> = self
            .near
            .iter()
            .map(|&c| {
                if c == u32::MAX || coarse_fixed[c as usize] {
                    Vector3::zeros()
                } else {
                    wc[c as usize]
                }
            })
            .collect();
        let mut next = vec![Vector3::zeros(); n];
        for _ in 0..passes {
            each_vertex(&mut next, |i| {
                let ring = topo.ring(i);
                let mut acc = v[i];
                for &j in ring {
                    acc += v[j as usize];
                }
                acc / (ring.len() + 1) as Real
            });
            std::mem::swap(&mut v, &mut next);
        }
        for (vi, &fixed) in v.iter_mut().zip(fine_fixed) {
            if fixed {
                *vi = Vector3::zeros();
            }
        }
        v
    }
}
