//! The elastic formulation (design.md §7, [`Formulation::Elastic`], the
//! default): total curvature `E_T` minimised as an *energy* in rotated
//! frames, plus ARAP's stretch term and an area-preservation term, so that
//! a local step (one rotation per free vertex, one projection per
//! triangle) and a global step (one prefactored linear solve) are both
//! exact minimisers and the objective never grows.
//!
//! On the normalised rest mesh (mean edge length 1), with `Lbar` the
//! cotangent matrix (`Lbar_ij = ½(cot α_ij + cot β_ij)`, libigl's
//! `cotmatrix`), `c⁺_ij = max(Lbar_ij, 0)` (negative weights clamped, as
//! CGAL's ARAP does), `A_i` the mixed Voronoi areas, `L = diag(1/A) Lbar`,
//! `δ = L X`, `e_ij = x_j − x_i`, `F̃` the free vertices, `S = Σ A_i`:
//!
//! ```text
//!   E(Y, R, P) = Σ_{i ∈ F̃} Σ_{j ∈ N(i)} c_ij |(y_j − y_i) − R_i e_ij|²    (E1)
//!              + Σ_{i ∈ F̃} b_i |(L Y)_i − R_i δ_i|²                        (E2)
//!              + k_a Σ_t a_t ‖F_t(Y) − P_t‖²                                (E3)
//!   c_ij = (k_s + k_b G_ij) c⁺_ij,   b_i = k_L λ2 k_b A_i,   k_b = β S,
//!   G_ij = (G_i + G_j)/2,   G_i = min(max(H_i² − K_i, 0), 1), 0 on the boundary.
//! ```
//!
//! - At `k_L = λ2 = 1` (the defaults), `E2` plus the `G` part of `E1` is `k_b E_T(d)`,
//!   `E_T(d) = ‖L d‖²_W + 2 ‖∇d‖²_G`: paper eq. (12) as an energy (its
//!   gradient is `2 W (L² − 2GL) d`, eq. (24)'s operator), measured in the
//!   frames `R_i`. `E2` is also the paper's detail term (eq. (16)) with
//!   `δ̂_i = R_i δ_i`; `λ2` weights it.
//! - `k_s Σ c⁺ |…|²` is ARAP's spokes energy (Sorkine & Alexa 2007): it
//!   resists the stretch Laplacian-type terms let through.
//! - `E3`: `F_t` is triangle `t`'s 3×2 deformation gradient, `a_t` its rest
//!   area, `P_t` the nearest 3×2 matrix with singular values `d, 1/d`
//!   (Projective Dynamics' area constraint, Bouaziz et al. 2014): it keeps
//!   cross-sections from shrinking under twist.
//! - Rows centred at constrained vertices are dropped (their rotations are
//!   not unknowns); spokes from a free vertex into a constrained one stay.
//! - `k_s` (stretch), `β` (bending), `λ2` (detail) and `k_a` (area) are
//!   dimensionless: `E1` and `E3` scale as length², `E2` is scale-free and
//!   `k_b = β S` restores the balance; all three are integrals whose
//!   discretisations converge under refinement, so neither the mesh's scale
//!   nor its resolution changes the pose.
//! - `G` is capped at `1/h²` (1 on the normalised mesh): on sliver
//!   vertices the discrete `H² − K` reaches 10³–10⁴, which only stiffens
//!   single spokes and slows the iteration.
//!
//! Expanded, `E = Yᵀ Q Y − 2 Yᵀ g(R, P) + const` with the constant
//! symmetric positive semi-definite
//! `Q = K_c + Lbar diag(k_L λ2 k_b [i ∈ F̃] / A_i) Lbar − k_a Lbar`
//! (`K_c` the graph Laplacian of the kept spokes; `Σ_t a_t ‖F_t‖² =
//! −Yᵀ Lbar Y`, the Dirichlet energy) and
//! `g_v = −Σ_j c_vj ([v ∈ F̃] R_v + [j ∈ F̃] R_j) e_vj + k_L λ2 k_b (Lbar t)_v
//!        + k_a Σ_{t ∋ v} a_t (P_t B_tᵀ)ᵀ∂F_t/∂y_v`, `t_i = [i ∈ F̃] R_i δ_i`.
//! Global step (hard constraints): `Q_UU Δ_U = (g − Q Y)_U`. Local step:
//! `R_i = argmax tr(R_iᵀ M_i)`, `M_i = Σ_j c_ij (y_j − y_i) e_ijᵀ + b_i (LY)_i δ_iᵀ`,
//! and `P_t` from the SVD of `F_t`.
//!
//! [`Formulation::Elastic`]: super::Formulation::Elastic

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rayon::prelude::*;
use sprs::{CsMat, TriMat};

use super::params::{ElasticParams, Params};
use super::rotation::fit_rotation_quat;
use super::rotation::lanes::{fit_rotation_quat4, LANES};
use super::system::{add_soft_diagonal, partition, System};
use crate::mesh::{Mesh, Point, Real};

mod area;
mod area_lanes;
pub(crate) mod hessian;
mod residual;
mod residual_rows;

use crate::operators::Operators;
pub use area::project_area;
use area::{area_element, gradient, AreaElement, AreaForces};
use area_lanes::{project_area_lanes, LANES as AREA_LANES};
use dend_linalg::sparse::matmul;
use residual_rows::ResidualRows;

// Vertex count from which the local step runs on the rayon pool
// (the iteration's shared threshold, crates/dend/src/deform/parallel.rs).
use crate::deform::parallel::PARALLEL_MIN_VERTICES as PARALLEL_MIN;

/// Vertices or triangles per block of the local step's energy sum (a
/// multiple of [`LANES`]): each block is summed in order, then the
/// blocks' sums, so the sum does not depend on how the work was split.
const SUM_BLOCK: usize = 64 * LANES;

/// The cap of `G` on the normalised mesh (module docs).
pub const G_CAP: Real = 1.0;

/// The rest-mesh data of the elastic energy for one set of weights:
/// spokes (CSR over vertices, in ring order), bending weights and area
/// elements. Depends on the rest mesh and the weights only; the matrix `Q`
/// depends on the constrained set too ([`ElasticSet`]).
#[derive(Debug, Clone)]
pub struct ElasticOps {
    /// Spokes of vertex `i`: `ptr[i]..ptr[i + 1]`.
    ptr: Vec<usize>,
    /// The spoke's far vertex `j`.
    nbr: Vec<u32>,
    /// `c_ij`.
    c: Vec<Real>,
    /// `e_ij = x_j − x_i`.
    e: Vec<Point>,
    /// `b_i = k_L λ2 k_b A_i`.
    b: Vec<Real>,
    /// `k_i = Σ_j c_ij |e_ij|² + b_i |δ_i|²`: the rest part of vertex
    /// `i`'s energy terms.
    k_rest: Vec<Real>,
    /// `k_L λ2 k_b`.
    kbl: Real,
    /// `Q` with every row kept (the rows a constraint set drops are
    /// subtracted from it, see `system`).
    q_all: CsMat<Real>,
    /// `k_a`.
    ka: Real,
    area: Vec<AreaElement>,
    /// The area term's forces gathered per vertex (the residual's).
    area_forces: AreaForces,
    /// The residual's rows in factored form.
    rows: ResidualRows,
}

/// The elastic system of one constrained set: which vertices keep their
/// rows, and `Q` (`#V×#V`, CSR, symmetric).
#[derive(Debug, Clone)]
pub struct ElasticSet {
    /// Whether the rows centred at `i` (spokes, bending) are kept.
    pub(crate) free: Vec<bool>,
    /// Whether `R_i` is fitted by the local step (else it stays as set:
    /// a constrained vertex's rotation is its handle's).
    pub(crate) fit: Vec<bool>,
    /// `Q`.
    pub(crate) q: CsMat<Real>,
    /// [`ResidualRows::rest_turn`] of this set.
    rest_turn: Vec<Point>,
}

impl ElasticOps {
    /// Builds the spokes, bending weights and area elements of the elastic
    /// `weights`, with `params`' energy and `λ2`, on the rest mesh `mesh`
    /// with operators `ops`.
    pub fn new(mesh: &Mesh, ops: &Operators, params: &Params, weights: &ElasticParams) -> Self {
        let n = ops.num_vertices();
        let topo = mesh.topology();
        let surface: Real = ops.area.iter().sum();
        let kb = weights.bending * surface;
        let kg = kb * params.energy.gaussian_share();
        let kbl = params.lambda2 * weights.laplacian * kb;
        let g: Vec<Real> = (0..n)
            .map(|i| {
                if topo.is_boundary(i) {
                    0.0
                } else {
                    ops.g[i].clamp(0.0, G_CAP)
                }
            })
            .collect();
        let mut ptr = Vec::with_capacity(n + 1);
        ptr.push(0);
        let (mut nbr, mut c, mut e) = (Vec::new(), Vec::new(), Vec::new());
        let x = &ops.positions;
        for i in 0..n {
            for &j in topo.ring(i) {
                let ju = j as usize;
                let w = ops.lbar.get(i, ju).copied().unwrap_or(0.0).max(0.0);
                nbr.push(j);
                c.push((weights.stretch + kg * 0.5 * (g[i] + g[ju])) * w);
                e.push([x[ju][0] - x[i][0], x[ju][1] - x[i][1], x[ju][2] - x[i][2]]);
            }
            ptr.push(nbr.len());
        }
        let b: Vec<Real> = ops.area.iter().map(|&a| kbl * a).collect();
        let k_rest = (0..n)
            .map(|i| {
                let spokes: Real = (ptr[i]..ptr[i + 1])
                    .map(|s| c[s] * Vector3::from(e[s]).norm_squared())
                    .sum();
                spokes + b[i] * Vector3::from(ops.delta[i]).norm_squared()
            })
            .collect();
        let ka = weights.area;
        let area = if ka > 0.0 {
            mesh.triangles()
                .iter()
                .filter_map(|&t| area_element(x, t, ka))
                .collect()
        } else {
            Vec::new()
        };
        let area_forces = AreaForces::new(n, &area);
        let rows = ResidualRows::new(ops, (&ptr, &nbr), (&c, &e), &b, kbl, ka);
        let mut ops_ = ElasticOps {
            ptr,
            nbr,
            c,
            e,
            b,
            k_rest,
            kbl,
            ka,
            area,
            area_forces,
            rows,
            q_all: CsMat::zero((n, n)),
        };
        ops_.q_all = ops_.assemble_q(ops, &vec![true; n]);
        ops_
    }

    /// Memory held, in bytes.
    pub fn memory_bytes(&self) -> usize {
        self.ptr.len() * 8
            + self.nbr.len() * 4
            + self.c.len() * 8
            + self.e.len() * 24
            + self.b.len() * 8
            + self.area.len() * std::mem::size_of::<AreaElement>()
            + self.area_forces.memory_bytes()
            + self.rows.memory_bytes()
            + self.q_all.nnz() * 16
    }

    /// `Q` of the constrained set `constrained` (module docs).
    pub fn system(&self, ops: &Operators, constrained: &[u32]) -> ElasticSet {
        let n = ops.num_vertices();
        // Rows centred at constrained vertices are dropped and their
        // rotations are not fitted. Measured against keeping them (rotations
        // fitted, or pinned to the handle's): dropping bends the tube of the
        // 135° twist evenly (twist deviation 3.8° against 5.8–7.2° on the
        // generated bar, measured at the slabs' centres before stop 28,
        // which put an exact ramp up to 3.4° off: 1.9° now for dropping)
        // and keeps limbs closer to ARAP (dino limb mean distortion 1.50x
        // against 1.67–1.79x); keeping them bends the 120° cylinder more
        // evenly (CV 0.45 against 0.49).
        let mut free = vec![true; n];
        for &v in constrained {
            free[v as usize] = false;
        }
        let fit = free.clone();
        // Q of this set = Q of all rows (built once per rest mesh and
        // weights) minus the rows centred at constrained vertices: a few
        // entries per constrained vertex instead of a sparse product per
        // constraint set; assembled directly in the rare case the full Q
        // lacks an entry the subtraction needs
        let q = self
            .drop_rows(ops, &free)
            .unwrap_or_else(|| self.assemble_q(ops, &free));
        let rest_turn = self.rows.rest_turn(&free);
        ElasticSet {
            free,
            fit,
            q,
            rest_turn,
        }
    }

    /// `Q` with the rows centred at the vertices where `free` is false
    /// removed from `q_all`, or `None` when an entry it must change is not
    /// stored.
    fn drop_rows(&self, ops: &Operators, free: &[bool]) -> Option<CsMat<Real>> {
        let mut q = self.q_all.clone();
        for c in (0..free.len()).filter(|&c| !free[c]) {
            for s in self.ptr[c]..self.ptr[c + 1] {
                let (j, w) = (self.nbr[s] as usize, self.c[s]);
                if w != 0.0 {
                    *q.get_mut(c, c)? -= w;
                    *q.get_mut(j, j)? -= w;
                    *q.get_mut(c, j)? += w;
                    *q.get_mut(j, c)? += w;
                }
            }
            if self.kbl > 0.0 {
                // − kbl Lbar[:, c] L[c, :] (Lbar symmetric)
                let (lbar_c, l_c) = (ops.lbar.outer_view(c)?, ops.l.outer_view(c)?);
                for (i, &a) in lbar_c.iter() {
                    for (k, &b) in l_c.iter() {
                        *q.get_mut(i, k)? -= self.kbl * a * b;
                    }
                }
            }
        }
        Some(q)
    }

    /// `Q` assembled from its terms for the rows where `free` is true.
    ///
    /// With the Laplacian term, `Lbar diag(·) L` has the widest pattern (the
    /// 2-ring, which holds the spokes' and `Lbar`'s 1-ring) and its product
    /// is computed first; the spokes and the area term are then added into
    /// its entries in place ([`ElasticOps::add_into_product`]): no triplets
    /// to sort and no sparse sums, which halved the factor's assembly time
    /// (camel 9770: 51 → 28 ms, feline 50k: 322 → 159 ms, best of 8 runs
    /// each on one loaded host).
    fn assemble_q(&self, ops: &Operators, free: &[bool]) -> CsMat<Real> {
        if self.kbl > 0.0 {
            let mut q = matmul(&ops.lbar, &self.scaled_l(ops, free));
            if self.add_into_product(ops, free, &mut q).is_some() {
                return q;
            }
        }
        self.assemble_q_from_triplets(ops, free)
    }

    /// `diag(kbl [free]) L`, the right factor of the Laplacian term.
    fn scaled_l(&self, ops: &Operators, free: &[bool]) -> CsMat<Real> {
        let mut right = ops.l.clone();
        for (i, mut row) in right.outer_iterator_mut().enumerate() {
            let s = if free[i] { self.kbl } else { 0.0 };
            row.iter_mut().for_each(|(_, v)| *v *= s);
        }
        right
    }

    /// Adds `K_c` (the kept spokes) and `−k_a Lbar` into `q`'s stored
    /// entries, or `None` (with `q` part-updated) when one is not stored.
    fn add_into_product(&self, ops: &Operators, free: &[bool], q: &mut CsMat<Real>) -> Option<()> {
        for i in (0..free.len()).filter(|&i| free[i]) {
            for s in self.ptr[i]..self.ptr[i + 1] {
                let (j, w) = (self.nbr[s] as usize, self.c[s]);
                if w != 0.0 {
                    *q.get_mut(i, i)? += w;
                    *q.get_mut(j, j)? += w;
                    *q.get_mut(i, j)? -= w;
                    *q.get_mut(j, i)? -= w;
                }
            }
        }
        if self.ka > 0.0 {
            for (i, row) in ops.lbar.outer_iterator().enumerate() {
                for (j, &v) in row.iter() {
                    *q.get_mut(i, j)? -= self.ka * v;
                }
            }
        }
        Some(())
    }

    /// [`ElasticOps::assemble_q`] from triplets and sparse sums, for any
    /// weights (the reference the in-place assembly is tested against).
    fn assemble_q_from_triplets(&self, ops: &Operators, free: &[bool]) -> CsMat<Real> {
        let n = free.len();
        // K_c: each kept spoke adds c to both diagonals, −c off them
        let mut k = TriMat::new((n, n));
        for i in (0..n).filter(|&i| free[i]) {
            for s in self.ptr[i]..self.ptr[i + 1] {
                let (j, w) = (self.nbr[s] as usize, self.c[s]);
                if w != 0.0 {
                    k.add_triplet(i, i, w);
                    k.add_triplet(j, j, w);
                    k.add_triplet(i, j, -w);
                    k.add_triplet(j, i, -w);
                }
            }
        }
        let mut q: CsMat<Real> = k.to_csr();
        if self.kbl > 0.0 {
            // Lᵀ diag(b ∘ free) L = Lbar diag(kbl [free] / A) Lbar
            q = &q + &matmul(&ops.lbar, &self.scaled_l(ops, free));
        }
        if self.ka > 0.0 {
            let mut area = ops.lbar.clone();
            area.map_inplace(|v| -self.ka * v);
            q = &q + &area;
        }
        q
    }

    /// The local step: for every free vertex the rotation `R_i` maximising
    /// `tr(R_iᵀ M_i)`, warm-started from `rot` and written back to it, and
    /// for every triangle its projection `P_t` into `proj` (when `fit`;
    /// otherwise `rot` and `proj` are kept as they are: the linear detail
    /// term, all identity), given `ly = L Y`. Returns `E(Y, R, P)`.
    #[allow(clippy::too_many_arguments)]
    pub fn local_step(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        y: &[Point],
        ly: &[Point],
        rot: &mut [UnitQuaternion<Real>],
        proj: &mut [[Real; 6]],
        fit: bool,
    ) -> Real {
        self.local_step_from(set, ops, (y, ly), (None, rot), proj, fit)
    }

    /// [`Self::local_step`] warm-started from `warm` when given (copied
    /// into `rot` block by block as the step reaches it, not in a pass of
    /// its own: a trial step starts from the accepted rotations).
    pub fn local_step_from(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        (y, ly): (&[Point], &[Point]),
        (warm, rot): (Option<&[UnitQuaternion<Real>]>, &mut [UnitQuaternion<Real>]),
        proj: &mut [[Real; 6]],
        fit: bool,
    ) -> Real {
        assert!(warm.is_none_or(|w| w.len() == rot.len()));
        // M_i and Σ_j c_ij |y_j − y_i|² + b_i |(LY)_i|² in one pass over the
        // spokes; then E_i = k_i + that − 2 tr(R_iᵀ M_i) with the rest
        // constant k_i = Σ_j c_ij |e_ij|² + b_i |δ_i|²
        let covariance = |i: usize| {
            let mut m = Matrix3::<Real>::zeros();
            let mut sq = 0.0;
            if !set.free[i] {
                return (m, sq);
            }
            let yi = y[i];
            for s in self.ptr[i]..self.ptr[i + 1] {
                let yj = y[self.nbr[s] as usize];
                let d = Vector3::new(yj[0] - yi[0], yj[1] - yi[1], yj[2] - yi[2]);
                m += self.c[s] * d * Vector3::from(self.e[s]).transpose();
                sq += self.c[s] * d.norm_squared();
            }
            if self.b[i] > 0.0 {
                let l = Vector3::from(ly[i]);
                m += self.b[i] * l * Vector3::from(ops.delta[i]).transpose();
                sq += self.b[i] * l.norm_squared();
            }
            (m, sq)
        };
        let energy_of = |i: usize, q: &UnitQuaternion<Real>, (m, sq): &(Matrix3<Real>, Real)| {
            if !set.free[i] {
                return 0.0;
            }
            let r = q.to_rotation_matrix();
            let trace = r.matrix().component_mul(m).sum();
            // never below 0 (rounding near a perfect fit)
            (self.k_rest[i] + sq - 2.0 * trace).max(0.0)
        };
        let vertices = |(c, o): (usize, &mut [UnitQuaternion<Real>])| -> Real {
            let i0 = c * LANES;
            if let Some(w) = warm {
                o.copy_from_slice(&w[i0..i0 + o.len()]);
            }
            let mut cov = [(Matrix3::zeros(), 0.0); LANES];
            for (k, slot) in cov.iter_mut().take(o.len()).enumerate() {
                *slot = covariance(i0 + k);
            }
            if !fit {
                // keep the rotations
            } else if let Ok(group) = <&mut [UnitQuaternion<Real>; LANES]>::try_from(&mut *o) {
                let a = std::array::from_fn(|k| cov[k].0);
                fit_rotation_quat4(&a, group);
            } else {
                for (k, q) in o.iter_mut().enumerate() {
                    *q = fit_rotation_quat(&cov[k].0, q);
                }
            }
            o.iter()
                .enumerate()
                .map(|(k, q)| energy_of(i0 + k, q, &cov[k]))
                .sum()
        };
        let triangles = |(el, p): (&AreaElement, &mut [Real; 6])| -> Real {
            let f = gradient(y, el);
            if fit {
                *p = project_area(&f);
            }
            el.weight * (0..6).map(|k| (f[k] - p[k]).powi(2)).sum::<Real>()
        };
        // the energy summed block by block, the blocks' sums then in
        // order: the same rounding on any thread count and on both paths
        // (a parallel `sum` reduces in the order work was stolen, which
        // changed the objective's last bits from run to run)
        // (AVX2 where the CPU has it: the same arithmetic, `dend_linalg::cpu`)
        let vertex_block = |(b, block): (usize, &mut [UnitQuaternion<Real>])| -> Real {
            let first = b * SUM_BLOCK / LANES;
            dend_linalg::cpu::with_avx2_fma(|| {
                block
                    .chunks_mut(LANES)
                    .enumerate()
                    .map(|(c, o)| vertices((first + c, o)))
                    .sum()
            })
        };
        // eight projections side by side (`area_lanes`), bit for bit
        let triangle_block = |(els, ps): (&[AreaElement], &mut [[Real; 6]])| -> Real {
            els.chunks(AREA_LANES)
                .zip(ps.chunks_mut(AREA_LANES))
                .flat_map(|(els, ps)| {
                    let mut energy = [0.0; AREA_LANES];
                    if let (Ok(els), Ok(ps), true) = (
                        <&[AreaElement; AREA_LANES]>::try_from(els),
                        <&mut [[Real; 6]; AREA_LANES]>::try_from(&mut *ps),
                        fit,
                    ) {
                        let f: [[Real; 6]; AREA_LANES] =
                            std::array::from_fn(|k| gradient(y, &els[k]));
                        *ps = project_area_lanes(&f);
                        for k in 0..AREA_LANES {
                            energy[k] = els[k].weight
                                * (0..6).map(|c| (f[k][c] - ps[k][c]).powi(2)).sum::<Real>();
                        }
                    } else {
                        for (k, pair) in els.iter().zip(ps.iter_mut()).enumerate() {
                            energy[k] = triangles(pair);
                        }
                    }
                    energy.into_iter().take(els.len())
                })
                .sum()
        };
        let (ev, et): (Vec<Real>, Vec<Real>) = if rot.len() >= PARALLEL_MIN {
            (
                rot.par_chunks_mut(SUM_BLOCK)
                    .enumerate()
                    .map(vertex_block)
                    .collect(),
                self.area
                    .par_chunks(SUM_BLOCK)
                    .zip(proj.par_chunks_mut(SUM_BLOCK))
                    .map(triangle_block)
                    .collect(),
            )
        } else {
            (
                rot.chunks_mut(SUM_BLOCK)
                    .enumerate()
                    .map(vertex_block)
                    .collect(),
                self.area
                    .chunks(SUM_BLOCK)
                    .zip(proj.chunks_mut(SUM_BLOCK))
                    .map(triangle_block)
                    .collect(),
            )
        };
        ev.iter().sum::<Real>() + et.iter().sum::<Real>()
    }

    /// Area elements (the length of the `proj` buffer of [`Self::local_step`]).
    pub fn num_area_elements(&self) -> usize {
        self.area.len()
    }

    /// The first vertex of each area element (the vertex whose rotation
    /// turns its target), in the order of the projections.
    pub fn area_first_vertices(&self) -> impl Iterator<Item = usize> + '_ {
        self.area.iter().map(|el| el.v[0] as usize)
    }

    /// The area targets of the rest state rotated per triangle by its first
    /// vertex's rotation (`P_t = R_{t0} F_t(X)`): the projections consistent
    /// with rotations `rot` before any local step.
    pub fn rotated_rest_projections(
        &self,
        x: &[Point],
        rot: &[UnitQuaternion<Real>],
        proj: &mut [[Real; 6]],
    ) {
        for (el, p) in self.area.iter().zip(proj.iter_mut()) {
            let f = gradient(x, el);
            let r = rot[el.v[0] as usize].to_rotation_matrix();
            let c0 = r * Vector3::new(f[0], f[1], f[2]);
            let c1 = r * Vector3::new(f[3], f[4], f[5]);
            *p = [c0[0], c0[1], c0[2], c1[0], c1[1], c1[2]];
        }
    }
}

/// The elastic formulation's system of one constraint set: the unknowns
/// (free vertices; every active vertex with soft constraints) and
/// `M = Q_UU` (plus `λ1 q̄` on the constrained diagonal with soft
/// constraints, `q̄` the mean diagonal of `Q`, so that `λ1` is
/// dimensionless). There are no stacked rows: `rows` are the free
/// vertices (with hard constraints also the unknowns).
pub(crate) fn elastic_system(
    set: &ElasticSet,
    params: &Params,
    constrained: &[u32],
    active: &[bool],
) -> System {
    let q = &set.q;
    let n = q.rows();
    let soft = params.lambda1 > 0.0;
    let (rows, unknowns, col_of) = partition(n, constrained, active, soft);
    let mean_diag = (0..n)
        .map(|i| q.get(i, i).copied().unwrap_or(0.0))
        .sum::<Real>()
        / (active.iter().filter(|&&a| a).count().max(1) as Real);
    let lambda1 = params.lambda1 * mean_diag;
    let mut indptr = Vec::with_capacity(unknowns.len() + 1);
    indptr.push(0);
    let (mut indices, mut data) = (Vec::new(), Vec::new());
    for &u in &unknowns {
        let u = u as usize;
        if let Some(row) = q.outer_view(u) {
            for (j, &v) in row.iter() {
                let k = col_of[j];
                if k != u32::MAX {
                    indices.push(k as usize);
                    data.push(v);
                }
            }
        }
        indptr.push(indices.len());
    }
    let k = unknowns.len();
    let mut m = CsMat::new((k, k), indptr, indices, data);
    if soft {
        // λ1 on the constrained diagonal, also where Q has no entry (a
        // handle vertex whose neighbours are all constrained: no kept row
        // reaches it when the area term is off)
        m = add_soft_diagonal(&m, constrained, &col_of, lambda1);
    }
    System {
        row_weight: Vec::new(),
        sqrt_lambda2: params.lambda2.sqrt(),
        rows,
        unknowns,
        col_of,
        m,
        constrained: constrained.to_vec(),
        lambda1,
    }
}

#[cfg(test)]
mod tests;
