//! The elastic formulation (dend.md §9, [`Formulation::Elastic`], the
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
//!   c_ij = (k_s + k_b G_ij) c⁺_ij,   b_i = λ2 k_b A_i,   k_b = β S,
//!   G_ij = (G_i + G_j)/2,   G_i = min(max(H_i² − K_i, 0), 1), 0 on the boundary.
//! ```
//!
//! - `k_b (E2 + the G part of E1)` at `λ2 = 1` is `k_b E_T(d)`,
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
//! `Q = K_c + Lbar diag(λ2 k_b [i ∈ F̃] / A_i) Lbar − k_a Lbar`
//! (`K_c` the graph Laplacian of the kept spokes; `Σ_t a_t ‖F_t‖² =
//! −Yᵀ Lbar Y`, the Dirichlet energy) and
//! `g_v = −Σ_j c_vj ([v ∈ F̃] R_v + [j ∈ F̃] R_j) e_vj + λ2 k_b (Lbar t)_v
//!        + k_a Σ_{t ∋ v} a_t (P_t B_tᵀ)ᵀ∂F_t/∂y_v`, `t_i = [i ∈ F̃] R_i δ_i`.
//! Global step (hard constraints): `Q_UU Δ_U = (g − Q Y)_U`. Local step:
//! `R_i = argmax tr(R_iᵀ M_i)`, `M_i = Σ_j c_ij (y_j − y_i) e_ijᵀ + b_i (LY)_i δ_iᵀ`,
//! and `P_t` from the SVD of `F_t`.
//!
//! [`Formulation::Elastic`]: super::Formulation::Elastic

use nalgebra::{Matrix2, Matrix3, UnitQuaternion, Vector2, Vector3};
use rayon::prelude::*;
use sprs::{CsMat, TriMat};

use super::params::{Energy, Params};
use super::rotation::{fit_rotation_quat, fit_rotation_quat4, LANES};
use crate::mesh::{Mesh, Point, Real};
use crate::operators::Operators;
use dend_linalg::sparse::matmul;

/// Element count from which the local step runs on the rayon pool.
const PARALLEL_MIN: usize = 2048;

/// The cap of `G` on the normalised mesh (module docs).
pub const G_CAP: Real = 1.0;

/// One triangle of the area term: its vertices, `B = D_m⁻¹` (the rest
/// edges in an orthonormal frame of the rest triangle, inverted) and
/// `k_a a_t`.
#[derive(Debug, Clone, Copy)]
struct AreaElement {
    v: [u32; 3],
    b: Matrix2<Real>,
    weight: Real,
}

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
    /// `b_i = λ2 k_b A_i`.
    b: Vec<Real>,
    /// `k_i = Σ_j c_ij |e_ij|² + b_i |δ_i|²`: the rest part of vertex
    /// `i`'s energy terms.
    k_rest: Vec<Real>,
    /// `λ2 k_b`.
    kbl: Real,
    /// `k_a`.
    ka: Real,
    area: Vec<AreaElement>,
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
}

impl ElasticOps {
    /// Builds the spokes, bending weights and area elements of `params`'
    /// weights on the rest mesh `mesh` with operators `ops`.
    pub fn new(mesh: &Mesh, ops: &Operators, params: &Params) -> Self {
        let n = ops.num_vertices();
        let topo = mesh.topology();
        let surface: Real = ops.area.iter().sum();
        let kb = params.bending * surface;
        let kg = match params.energy {
            Energy::ThinPlate => 0.0,
            _ => kb,
        };
        let kbl = params.lambda2 * kb;
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
                c.push((params.stretch + kg * 0.5 * (g[i] + g[ju])) * w);
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
        let ka = params.area;
        let area = if ka > 0.0 {
            mesh.triangles()
                .iter()
                .filter_map(|&t| area_element(x, t, ka))
                .collect()
        } else {
            Vec::new()
        };
        ElasticOps {
            ptr,
            nbr,
            c,
            e,
            b,
            k_rest,
            kbl,
            ka,
            area,
        }
    }

    /// Memory held, in bytes.
    pub fn memory_bytes(&self) -> usize {
        self.ptr.len() * 8
            + self.nbr.len() * 4
            + self.c.len() * 8
            + self.e.len() * 24
            + self.b.len() * 8
            + self.area.len() * std::mem::size_of::<AreaElement>()
    }

    /// `Q` of the constrained set `constrained` (module docs).
    pub fn system(&self, ops: &Operators, constrained: &[u32]) -> ElasticSet {
        let n = ops.num_vertices();
        // Rows centred at constrained vertices are dropped and their
        // rotations are not fitted. Measured against keeping them (rotations
        // fitted, or pinned to the handle's): dropping bends the tube of the
        // 135° twist evenly (twist deviation 3.8° against 5.8–7.2° on the
        // generated bar) and keeps limbs closer to ARAP (dino limb mean
        // distortion 1.50x against 1.67–1.79x); keeping them bends the
        // 120° cylinder more evenly (CV 0.45 against 0.49).
        let mut free = vec![true; n];
        for &v in constrained {
            free[v as usize] = false;
        }
        let fit = free.clone();
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
            let mut right = ops.l.clone();
            for (i, mut row) in right.outer_iterator_mut().enumerate() {
                let s = if free[i] { self.kbl } else { 0.0 };
                row.iter_mut().for_each(|(_, v)| *v *= s);
            }
            q = &q + &matmul(&ops.lbar, &right);
        }
        if self.ka > 0.0 {
            let mut area = ops.lbar.clone();
            area.map_inplace(|v| -self.ka * v);
            q = &q + &area;
        }
        ElasticSet { free, fit, q }
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
        if rot.len() >= PARALLEL_MIN {
            let ev: Real = rot.par_chunks_mut(LANES).enumerate().map(vertices).sum();
            let et: Real = self
                .area
                .par_iter()
                .zip(proj.par_iter_mut())
                .map(triangles)
                .sum();
            ev + et
        } else {
            let ev: Real = rot.chunks_mut(LANES).enumerate().map(vertices).sum();
            let et: Real = self.area.iter().zip(proj.iter_mut()).map(triangles).sum();
            ev + et
        }
    }

    /// Area elements (the length of the `proj` buffer of [`Self::local_step`]).
    pub fn num_area_elements(&self) -> usize {
        self.area.len()
    }

    /// `out = g(R, P) − Q Y` (module docs), `#V`: the negative half-gradient
    /// of `E` in `Y` at fixed `R` and `P`. `t` (`#V`) and `rm` (`#V`, the
    /// rotations as matrices) are scratch.
    #[allow(clippy::too_many_arguments)]
    pub fn residual(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        y: &[Point],
        rot: &[UnitQuaternion<Real>],
        proj: &[[Real; 6]],
        (t, rm): (&mut [Point], &mut [Matrix3<Real>]),
        out: &mut [Point],
    ) {
        let n = y.len();
        // R_i as a matrix (zero where the rows are dropped) and
        // t_i = [i free] R_i δ_i
        for i in 0..n {
            rm[i] = if set.free[i] {
                rot[i].to_rotation_matrix().into_inner()
            } else {
                Matrix3::zeros()
            };
            t[i] = if self.b[i] > 0.0 {
                (rm[i] * Vector3::from(ops.delta[i])).into()
            } else {
                [0.0; 3]
            };
        }
        let (t, rm): (&[Point], &[Matrix3<Real>]) = (t, rm);
        // out = kbl Lbar t − Q Y − Σ_j c_vj ([v free] R_v + [j free] R_j) e_vj
        let row = |(v, o): (usize, &mut Point)| {
            let mut acc = [0.0; 3];
            if self.kbl > 0.0 {
                if let Some(r) = ops.lbar.outer_view(v) {
                    for (j, &w) in r.iter() {
                        for a in 0..3 {
                            acc[a] += self.kbl * w * t[j][a];
                        }
                    }
                }
            }
            if let Some(r) = set.q.outer_view(v) {
                for (j, &w) in r.iter() {
                    for a in 0..3 {
                        acc[a] -= w * y[j][a];
                    }
                }
            }
            // c is symmetric and e_jv = −e_vj: the spokes into v gather too
            for s in self.ptr[v]..self.ptr[v + 1] {
                let j = self.nbr[s] as usize;
                let re = (rm[v] + rm[j]) * Vector3::from(self.e[s]);
                for a in 0..3 {
                    acc[a] -= self.c[s] * re[a];
                }
            }
            *o = acc;
        };
        if n >= PARALLEL_MIN {
            out.par_iter_mut().enumerate().for_each(row);
        } else {
            out.iter_mut().enumerate().for_each(row);
        }
        // area: + a_t (P_t Bᵀ) scattered onto the triangle's vertices
        for (el, p) in self.area.iter().zip(proj) {
            let pm = nalgebra::Matrix3x2::new(p[0], p[3], p[1], p[4], p[2], p[5]);
            let h = el.weight * pm * el.b.transpose();
            let [v0, v1, v2] = el.v.map(|v| v as usize);
            for a in 0..3 {
                out[v1][a] += h[(a, 0)];
                out[v2][a] += h[(a, 1)];
                out[v0][a] -= h[(a, 0)] + h[(a, 1)];
            }
        }
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

/// The area element of triangle `t` on positions `x`, or `None` when it
/// is degenerate.
fn area_element(x: &[Point], t: [u32; 3], ka: Real) -> Option<AreaElement> {
    let p = t.map(|v| Vector3::from(x[v as usize]));
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let n = e1.cross(&e2);
    let area = 0.5 * n.norm();
    let u = e1.try_normalize(1e-300)?;
    let v = n.cross(&u).try_normalize(1e-300)?;
    let dm = Matrix2::new(e1.dot(&u), e2.dot(&u), e1.dot(&v), e2.dot(&v));
    let b = dm.try_inverse()?;
    (area > 0.0 && b.iter().all(|v| v.is_finite())).then_some(AreaElement {
        v: t,
        b,
        weight: ka * area,
    })
}

/// `F = [y1 − y0, y2 − y0] B`, column-major `[F00, F10, F20, F01, F11, F21]`.
fn gradient(y: &[Point], el: &AreaElement) -> [Real; 6] {
    let [v0, v1, v2] = el.v.map(|v| Vector3::from(y[v as usize]));
    let (e1, e2) = (v1 - v0, v2 - v0);
    let c0 = e1 * el.b[(0, 0)] + e2 * el.b[(1, 0)];
    let c1 = e1 * el.b[(0, 1)] + e2 * el.b[(1, 1)];
    [c0[0], c0[1], c0[2], c1[0], c1[1], c1[2]]
}

/// The nearest 3×2 matrix to `f` (column-major) with singular values
/// `d, 1/d` (Frobenius norm): from `F = U diag(σ1, σ2) Vᵀ`,
/// `P = U diag(d, 1/d) Vᵀ` with `d` the positive root of
/// `d⁴ − σ1 d³ + σ2 d − 1 = 0` minimising `(d − σ1)² + (1/d − σ2)²`.
pub fn project_area(f: &[Real; 6]) -> [Real; 6] {
    let c0 = Vector3::new(f[0], f[1], f[2]);
    let c1 = Vector3::new(f[3], f[4], f[5]);
    // FᵀF = V Σ² Vᵀ, in closed form: [[a, b], [b, c]]
    let (a, b, c) = (c0.dot(&c0), c0.dot(&c1), c1.dot(&c1));
    let half = 0.5 * (a - c);
    let r = (half * half + b * b).sqrt();
    let l1 = 0.5 * (a + c) + r;
    // l2 = det / l1: no cancellation when l2 ≪ l1
    let l2 = if l1 > 0.0 { (a * c - b * b) / l1 } else { 0.0 };
    // the eigenvector of l1: (b, l1 − a) or (l1 − c, b), the larger one
    let (e1, e2) = (Vector2::new(b, l1 - a), Vector2::new(l1 - c, b));
    let v1 = if e1.norm_squared() >= e2.norm_squared() {
        e1
    } else {
        e2
    }
    .try_normalize(1e-300)
    .unwrap_or_else(Vector2::x);
    let v2 = Vector2::new(-v1[1], v1[0]);
    let s1 = l1.max(0.0).sqrt();
    let s2 = l2.max(0.0).sqrt();
    let fv = |v: &Vector2<Real>| c0 * v[0] + c1 * v[1];
    let u1 = match (fv(&v1) / s1).try_normalize(1e-12) {
        Some(u) if s1 > 1e-12 => u,
        _ => Vector3::x(),
    };
    let w2 = fv(&v2) - u1 * u1.dot(&fv(&v2));
    let u2 = match w2.try_normalize(1e-300) {
        Some(u) if w2.norm() > 1e-14 * s1 => u,
        _ => {
            // any unit vector orthogonal to u1
            let a = if u1.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            };
            u1.cross(&a).normalize()
        }
    };
    let d = area_root(s1, s2);
    let p = u1 * v1.transpose() * d + u2 * v2.transpose() / d;
    [
        p[(0, 0)],
        p[(1, 0)],
        p[(2, 0)],
        p[(0, 1)],
        p[(1, 1)],
        p[(2, 1)],
    ]
}

/// `argmin_{d > 0} (d − σ1)² + (1/d − σ2)²` by Newton on the stationarity
/// quartic `d⁴ − σ1 d³ + σ2 d − 1 = 0` from `√(σ1/σ2)` (exact when
/// `σ1 = σ2`; 2–4 steps near rest), and again from `σ1` only if that does
/// not end at a local minimum; the best of the candidates and `d = 1`.
fn area_root(s1: Real, s2: Real) -> Real {
    let f = |d: Real| (d - s1) * (d - s1) + (1.0 / d - s2) * (1.0 / d - s2);
    let newton = |start: Real| -> Option<Real> {
        let mut d: Real = start.clamp(1e-6, 1e6);
        for _ in 0..40 {
            let d2 = d * d;
            let p = d2 * d2 - s1 * d2 * d + s2 * d - 1.0;
            let dp = 4.0 * d2 * d - 3.0 * s1 * d2 + s2;
            if dp.abs() < 1e-300 {
                return None;
            }
            let next = (d - p / dp).clamp(d * 0.1, d * 10.0);
            let done = (next - d).abs() <= 1e-14 * d;
            d = next;
            if done {
                // a minimum of f: f'' = 2 + 6/d⁴ − 4 σ2/d³ > 0
                let d3 = d * d * d;
                let convex = 2.0 + 6.0 / (d3 * d) - 4.0 * s2 / d3 > 0.0;
                return (d.is_finite() && d > 0.0 && convex).then_some(d);
            }
        }
        None
    };
    let mut best = (f(1.0), 1.0);
    let first = newton((s1 / s2.max(1e-12)).sqrt());
    let candidates = match first {
        Some(d) => [Some(d), None],
        None => [None, newton(s1.max(1e-6))],
    };
    for d in candidates.into_iter().flatten() {
        if f(d) < best.0 {
            best = (f(d), d);
        }
    }
    best.1
}

/// `out = L y`, `#V`.
pub fn laplacian(ops: &Operators, y: &[Point], out: &mut [Point]) {
    let row = |(v, o): (usize, &mut Point)| {
        let mut acc = [0.0; 3];
        if let Some(r) = ops.l.outer_view(v) {
            for (j, &w) in r.iter() {
                for a in 0..3 {
                    acc[a] += w * y[j][a];
                }
            }
        }
        *o = acc;
    };
    if y.len() >= PARALLEL_MIN {
        out.par_iter_mut().enumerate().for_each(row);
    } else {
        out.iter_mut().enumerate().for_each(row);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_area_projection_has_unit_determinant_and_fixes_rotations() {
        // a rotation-like F (orthonormal columns) is its own projection
        let f = [0.6, 0.8, 0.0, 0.0, 0.0, 1.0];
        let p = project_area(&f);
        for k in 0..6 {
            assert!((p[k] - f[k]).abs() < 1e-12, "{p:?}");
        }
        // a scaled F goes to singular values d, 1/d (product 1) and is
        // nearer to F than the unscaled rotation is
        for (s1, s2) in [(2.0, 0.5), (0.5, 0.4), (3.0, 1.0), (1.0, 1e-9)] {
            let f = [s1, 0.0, 0.0, 0.0, s2, 0.0];
            let p = project_area(&f);
            let (d1, d2) = (p[0], p[4]);
            assert!((d1 * d2 - 1.0).abs() < 1e-9, "{s1} {s2}: {p:?}");
            let dist = |a: Real, b: Real| (a - s1).powi(2) + (b - s2).powi(2);
            assert!(dist(d1, d2) <= dist(1.0, 1.0) + 1e-12);
            // stationary: no better d on a fine grid
            for k in 1..2000 {
                let d = k as Real * 0.005;
                assert!(dist(d1, d2) <= dist(d, 1.0 / d) + 1e-9, "{s1} {s2} d {d}");
            }
        }
    }
}
