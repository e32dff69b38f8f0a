//! The detail term's target `δ̂` (design.md §6; paper eqs. 25–28) and the
//! local rotations `T_i` (design.md §6.4).
//!
//! STEP 1 ([`Mu::new`]) runs once per rest mesh; STEP 2 ([`Mu::delta_hat`])
//! and [`local_rotations`] run every iteration and allocate nothing.

use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::params::Mode;
use super::rotation::fit_rotation_quat;
use super::rotation::lanes::{fit_rotation_quat4, LANES};
use crate::mesh::{cross, norm, sub, Point, Real, Topology};

// Vertex count from which per-vertex loops run on the rayon pool
// (the iteration's shared threshold, crates/dend/src/deform/parallel.rs).
use super::parallel::PARALLEL_MIN_VERTICES as PARALLEL_MIN;

/// The per-vertex coefficients `μ^i` of STEP 1 (paper eq. 25), for one mode.
///
/// Columns of vertex `i`'s 3×k system, in this order:
/// - one per ring face `(i, j_t, j_{t+1})`: the face normal
///   `n_t = (X_{j_t} - X_i) × (X_{j_{t+1}} - X_i)` (the paper's
///   `(X_j - X_i) ⊗ (X_{j-1} - X_i)` up to sign, which `μ` absorbs), divided
///   by the ring's mean rest edge length `ℓ̄_i` in [`Mode::Default`];
/// - [`Mode::Default`] only (design.md §6.1): one per ring neighbour, the edge
///   `X_j - X_i`. These make `d_i(X) = δ_i` exact at rest even where `δ_i` has
///   tangential parts and the ring is nearly planar.
///
/// `μ^i` is the minimum-norm solution (pseudo-inverse through the 3×3 Gram
/// matrix, equivalent to the SVD solution).
#[derive(Debug, Clone)]
pub struct Mu {
    mode: Mode,
    offsets: Vec<u32>,
    mu: Vec<Real>,
    inv_ring_len: Vec<Real>,
    delta_norm: Vec<Real>,
}

/// `G⁺ b` for the symmetric positive semi-definite Gram matrix `G`: the
/// minimum-norm least-squares solution, with eigenvalues below
/// `1e-12 λ_max` treated as zero. When `G` is that well conditioned (its
/// smallest eigenvalue is at least `det G / tr(G)²`, a lower bound, above
/// `1e-12 tr G`) `G⁺ = G⁻¹` and the 3×3 system is solved by Cramer's rule;
/// otherwise (flat or degenerate rings) through the eigendecomposition.
fn min_norm_solve(gram: &Matrix3<Real>, b: Point) -> Vector3<Real> {
    let tr = gram.trace();
    let h = [
        gram[(0, 0)],
        gram[(1, 1)],
        gram[(2, 2)],
        gram[(0, 1)],
        gram[(0, 2)],
        gram[(1, 2)],
    ];
    let [h00, h11, h22, h01, h02, h12] = h;
    let c00 = h11 * h22 - h12 * h12;
    let c01 = h02 * h12 - h01 * h22;
    let c02 = h01 * h12 - h02 * h11;
    let det = h00 * c00 + h01 * c01 + h02 * c02;
    if tr > 0.0 && det / (tr * tr) > 1e-12 * tr {
        let c11 = h00 * h22 - h02 * h02;
        let c12 = h01 * h02 - h00 * h12;
        let c22 = h00 * h11 - h01 * h01;
        let inv = 1.0 / det;
        return Vector3::new(
            (c00 * b[0] + c01 * b[1] + c02 * b[2]) * inv,
            (c01 * b[0] + c11 * b[1] + c12 * b[2]) * inv,
            (c02 * b[0] + c12 * b[1] + c22 * b[2]) * inv,
        );
    }
    let eig = SymmetricEigen::new(*gram);
    let lmax = eig.eigenvalues.iter().cloned().fold(0.0, Real::max);
    let mut pinv = Matrix3::<Real>::zeros();
    for e in 0..3 {
        let lam = eig.eigenvalues[e];
        if lam > 1e-12 * lmax && lam > 0.0 {
            let v = eig.eigenvectors.column(e);
            pinv += v * v.transpose() / lam;
        }
    }
    pinv * Vector3::from(b)
}

impl Mu {
    /// STEP 1 on the rest positions `x` with Laplacian coordinates `delta`.
    pub fn new(mode: Mode, topo: &Topology, x: &[Point], delta: &[Point]) -> Self {
        let n = x.len();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0u32);
        for i in 0..n {
            let k = num_columns(mode, topo, i);
            offsets.push(offsets[i] + k as u32);
        }
        let mut mu = vec![0.0; *offsets.last().unwrap() as usize];
        let mut inv_ring_len = vec![1.0; n];
        // Solve each vertex independently; split `mu` by the offsets.
        let mut slices: Vec<&mut [Real]> = Vec::with_capacity(n);
        let mut rest = mu.as_mut_slice();
        for i in 0..n {
            let (a, b) = rest.split_at_mut((offsets[i + 1] - offsets[i]) as usize);
            slices.push(a);
            rest = b;
        }
        let solve = |(i, (out, inv_len)): (usize, (&mut &mut [Real], &mut Real))| {
            let ring = topo.ring(i);
            if ring.is_empty() {
                return;
            }
            let xi = x[i];
            if mode == Mode::Default {
                let l: Real = ring
                    .iter()
                    .map(|&j| norm(sub(x[j as usize], xi)))
                    .sum::<Real>()
                    / ring.len() as Real;
                *inv_len = 1.0 / l;
            }
            let cols = |k: usize| column(mode, topo, x, i, *inv_len, k);
            let m = out.len();
            let mut gram = Matrix3::<Real>::zeros();
            for k in 0..m {
                let c = Vector3::from(cols(k));
                gram += c * c.transpose();
            }
            let y = min_norm_solve(&gram, delta[i]);
            for (k, o) in out.iter_mut().enumerate() {
                *o = Vector3::from(cols(k)).dot(&y);
            }
        };
        if n >= PARALLEL_MIN {
            slices
                .par_iter_mut()
                .zip(inv_ring_len.par_iter_mut())
                .enumerate()
                .for_each(solve);
        } else {
            slices
                .iter_mut()
                .zip(inv_ring_len.iter_mut())
                .enumerate()
                .for_each(solve);
        }
        Mu {
            mode,
            offsets,
            mu,
            inv_ring_len,
            delta_norm: delta.iter().map(|&d| norm(d)).collect(),
        }
    }

    /// `d_i(Y) = Σ_k μ_k c_k(Y)` (paper eq. 27) for one vertex.
    pub fn d(&self, topo: &Topology, y: &[Point], i: usize) -> Point {
        let m = &self.mu[self.offsets[i] as usize..self.offsets[i + 1] as usize];
        let mut d = [0.0; 3];
        let ring = topo.ring(i);
        if m.is_empty() || ring.is_empty() {
            return d;
        }
        // The columns of `column`, in the same order and with the same
        // arithmetic (so the same rounding), without its per-column ring
        // lookups: each edge vector is formed once for the face columns.
        let len = ring.len();
        let faces = if topo.is_boundary(i) { len - 1 } else { len };
        let pi = y[i];
        let inv_len = self.inv_ring_len[i];
        let first = sub(y[ring[0] as usize], pi);
        let mut a = first;
        for (k, &mu) in m[..faces].iter().enumerate() {
            let b = if k + 1 < len {
                sub(y[ring[k + 1] as usize], pi)
            } else {
                first
            };
            let c = cross(a, b);
            let c = match self.mode {
                Mode::Default => [c[0] * inv_len, c[1] * inv_len, c[2] * inv_len],
                Mode::Paper => c,
            };
            d[0] += mu * c[0];
            d[1] += mu * c[1];
            d[2] += mu * c[2];
            a = b;
        }
        for (&mu, &j) in m[faces..].iter().zip(ring) {
            let c = sub(y[j as usize], pi);
            d[0] += mu * c[0];
            d[1] += mu * c[1];
            d[2] += mu * c[2];
        }
        d
    }

    /// STEP 2 (paper eqs. 27–28): `δ̂_i = d_i / |d_i| · |δ_i|` on the pose `y`,
    /// written into `out`. Where `|δ_i|` is ~0 (flat) `δ̂_i = d_i`; where
    /// `|d_i|` is 0, `δ̂_i = 0`. Never NaN for finite `y`.
    pub fn delta_hat(&self, topo: &Topology, y: &[Point], out: &mut [Point]) {
        let f = |(i, o): (usize, &mut Point)| {
            let d = self.d(topo, y, i);
            let dn = norm(d);
            let target = self.delta_norm[i];
            *o = if target <= 1e-14 {
                d
            } else if dn > 1e-300 {
                let s = target / dn;
                [d[0] * s, d[1] * s, d[2] * s]
            } else {
                [0.0; 3]
            };
        };
        if out.len() >= PARALLEL_MIN {
            out.par_iter_mut().enumerate().for_each(f);
        } else {
            out.iter_mut().enumerate().for_each(f);
        }
    }
}

fn num_columns(mode: Mode, topo: &Topology, i: usize) -> usize {
    let m = topo.ring(i).len();
    if m == 0 {
        return 0;
    }
    let faces = if topo.is_boundary(i) { m - 1 } else { m };
    match mode {
        Mode::Default => faces + m,
        Mode::Paper => faces,
    }
}

/// Column `k` of vertex `i`'s STEP 1 system on positions `p`.
#[inline]
fn column(mode: Mode, topo: &Topology, p: &[Point], i: usize, inv_len: Real, k: usize) -> Point {
    let ring = topo.ring(i);
    let m = ring.len();
    let faces = if topo.is_boundary(i) { m - 1 } else { m };
    let pi = p[i];
    if k < faces {
        let a = sub(p[ring[k] as usize], pi);
        let b = sub(p[ring[(k + 1) % m] as usize], pi);
        let c = cross(a, b);
        match mode {
            Mode::Default => [c[0] * inv_len, c[1] * inv_len, c[2] * inv_len],
            Mode::Paper => c,
        }
    } else {
        sub(p[ring[k - faces] as usize], pi)
    }
}

/// The local rotations `T_i` (design.md §6.4), one per vertex, fitted by
/// Procrustes on the 1-ring edges (the ARAP local step, Sorkine & Alexa 2007):
/// `T_i = argmin_{R ∈ SO(3)} Σ_j w_ij |(Y_j - Y_i) - R (X_j - X_i)|²`, with
/// `w_ij = max(cot α_ij + cot β_ij, 0)` (negative cotangents clamped) plus a
/// small uniform weight so that every ring edge counts.
/// Written into `out` as unit quaternions; `out`'s previous contents are the
/// warm start of [`fit_rotation_quat`] (Newton on SO(3); start from `I` when
/// no better guess exists). Unreferenced vertices get `I`.
pub fn local_rotations(
    topo: &Topology,
    weights: &RingWeights,
    x: &[Point],
    y: &[Point],
    out: &mut [UnitQuaternion<Real>],
) {
    // A = Σ_j w_ij (Y_j - Y_i)(X_j - X_i)ᵀ; T_i = argmax tr(Tᵀ A), fitted
    // four vertices at a time (bit-for-bit the one-vertex fit). A vertex
    // without neighbours has A = 0 and keeps the identity.
    let covariance = |i: usize| {
        let w = weights.of(i);
        let mut a = Matrix3::<Real>::zeros();
        for (k, &j) in topo.ring(i).iter().enumerate() {
            let e = Vector3::from(sub(x[j as usize], x[i]));
            let e2 = Vector3::from(sub(y[j as usize], y[i]));
            a += w[k] * e2 * e.transpose();
        }
        a
    };
    let f = |(c, o): (usize, &mut [UnitQuaternion<Real>])| {
        let i0 = c * LANES;
        for (k, q) in o.iter_mut().enumerate() {
            if topo.ring(i0 + k).is_empty() {
                *q = UnitQuaternion::identity();
            }
        }
        if let Ok(group) = <&mut [UnitQuaternion<Real>; LANES]>::try_from(&mut *o) {
            let a = std::array::from_fn(|k| covariance(i0 + k));
            fit_rotation_quat4(&a, group);
        } else {
            for (k, q) in o.iter_mut().enumerate() {
                *q = fit_rotation_quat(&covariance(i0 + k), q);
            }
        }
    };
    if out.len() >= PARALLEL_MIN {
        out.par_chunks_mut(LANES).enumerate().for_each(f);
    } else {
        out.chunks_mut(LANES).enumerate().for_each(f);
    }
}

/// Procrustes weights per ring neighbour, aligned with [`Topology::ring`].
#[derive(Debug, Clone)]
pub struct RingWeights {
    offsets: Vec<u32>,
    w: Vec<Real>,
}

impl RingWeights {
    /// `max(2 Lbar_ij, 0) + 0.01 · mean` for each ring neighbour `j` of `i`.
    pub fn new(topo: &Topology, lbar: &sprs::CsMat<Real>) -> Self {
        let n = lbar.rows();
        let mut offsets = Vec::with_capacity(n + 1);
        let mut w = Vec::new();
        offsets.push(0u32);
        for i in 0..n {
            let row = lbar.outer_view(i);
            let start = w.len();
            for &j in topo.ring(i) {
                let c = row.and_then(|r| r.get(j as usize).copied()).unwrap_or(0.0);
                w.push((2.0 * c).max(0.0));
            }
            let m = (w.len() - start).max(1) as Real;
            let mean = w[start..].iter().sum::<Real>() / m;
            let floor = if mean > 0.0 { 0.01 * mean } else { 1.0 };
            for v in &mut w[start..] {
                *v += floor;
            }
            offsets.push(w.len() as u32);
        }
        RingWeights { offsets, w }
    }

    fn of(&self, i: usize) -> &[Real] {
        &self.w[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;
    use crate::operators::Operators;
    use nalgebra::{Rotation3, Unit};
    use proptest::prelude::*;

    proptest! {
        /// `min_norm_solve` against the SVD's pseudo-inverse (an independent
        /// computation) on Gram matrices of 1 to 6 random columns: rank 1
        /// and 2 (flat and degenerate rings) and full rank.
        #[test]
        fn min_norm_solve_is_the_pseudo_inverse(
            c in proptest::collection::vec(-1.0f64..1.0, 18),
            m in 1usize..7,
            b in proptest::collection::vec(-1.0f64..1.0, 3),
        ) {
            let mut gram = Matrix3::zeros();
            for k in 0..m {
                let v = Vector3::new(c[3 * k], c[3 * k + 1], c[3 * k + 2]);
                gram += v * v.transpose();
            }
            let got = min_norm_solve(&gram, [b[0], b[1], b[2]]);
            let svd = gram.svd(true, true);
            let smax = svd.singular_values.max();
            let pinv = svd.pseudo_inverse(1e-12 * smax).unwrap();
            let expected = pinv * Vector3::new(b[0], b[1], b[2]);
            let s = svd.singular_values;
            let smin_kept = s.iter().cloned().filter(|&v| v > 1e-12 * smax).fold(f64::INFINITY, f64::min);
            // both are exact to rounding × the kept condition number
            let tol = 1e-9 * (smax / smin_kept) * (1.0 + expected.norm());
            prop_assert!((got - expected).norm() <= tol, "{} vs {} (m = {})", got, expected, m);
        }
    }

    /// An irregular open patch: a jittered grid lifted onto a saddle.
    fn saddle() -> Mesh {
        let k = 7;
        let mut p = Vec::new();
        for r in 0..k {
            for c in 0..k {
                let (x, y) = (
                    c as f64 + 0.31 * ((r * 7 + c * 3) % 5) as f64 / 5.0,
                    r as f64 + 0.27 * ((r * 2 + c * 5) % 7) as f64 / 7.0,
                );
                p.push([x, y, 0.05 * (x - 3.0) * (y - 3.0)]);
            }
        }
        let mut t = Vec::new();
        for r in 0..k as u32 - 1 {
            for c in 0..k as u32 - 1 {
                let v = r * k as u32 + c;
                t.push([v, v + 1, v + k as u32 + 1]);
                t.push([v, v + k as u32 + 1, v + k as u32]);
            }
        }
        Mesh::new(p, t).unwrap()
    }

    #[test]
    fn d_is_the_mu_weighted_sum_of_the_step1_columns() {
        // d_i(Y) = Σ_k μ_k c_k(Y) (eq. 27), summed column by column with
        // `column`, on a deformed pose, interior and boundary vertices, both
        // modes: the fused loop of `Mu::d` gives the same bits.
        let m = saddle();
        let ops = Operators::new(&m);
        let y: Vec<Point> = ops
            .positions
            .iter()
            .map(|p| [p[0] + 0.1 * p[1].sin(), p[1] * 1.2, p[2] + 0.3 * p[0]])
            .collect();
        for mode in [Mode::Default, Mode::Paper] {
            let mu = Mu::new(mode, m.topology(), &ops.positions, &ops.delta);
            for i in 0..m.num_vertices() {
                let coeffs = &mu.mu[mu.offsets[i] as usize..mu.offsets[i + 1] as usize];
                assert_eq!(coeffs.len(), num_columns(mode, m.topology(), i));
                let mut want = [0.0; 3];
                for (k, &c) in coeffs.iter().enumerate() {
                    let col = column(mode, m.topology(), &y, i, mu.inv_ring_len[i], k);
                    for a in 0..3 {
                        want[a] += c * col[a];
                    }
                }
                assert_eq!(mu.d(m.topology(), &y, i), want, "{mode:?} vertex {i}");
            }
        }
    }

    #[test]
    fn augmented_mu_reproduces_delta_at_rest() {
        let m = saddle();
        let ops = Operators::new(&m);
        let mu = Mu::new(Mode::Default, m.topology(), &ops.positions, &ops.delta);
        let mut out = vec![[0.0; 3]; m.num_vertices()];
        mu.delta_hat(m.topology(), &ops.positions, &mut out);
        for (a, b) in out.iter().zip(&ops.delta) {
            assert!(
                norm(sub(*a, *b)) < 1e-12 * (1.0 + norm(*b)),
                "{a:?} vs {b:?}"
            );
        }
    }

    #[test]
    fn cross_product_mu_misses_tangential_delta() {
        // design.md §6.1: the paper's columns cannot reproduce δ on irregular rings
        let m = saddle();
        let ops = Operators::new(&m);
        let mu = Mu::new(Mode::Paper, m.topology(), &ops.positions, &ops.delta);
        let mut out = vec![[0.0; 3]; m.num_vertices()];
        mu.delta_hat(m.topology(), &ops.positions, &mut out);
        let worst = out
            .iter()
            .zip(&ops.delta)
            .map(|(a, b)| norm(sub(*a, *b)))
            .fold(0.0, f64::max);
        assert!(worst > 1e-3, "paper μ unexpectedly exact: {worst}");
    }

    #[test]
    fn delta_hat_and_rotations_follow_a_rigid_motion() {
        let m = saddle();
        let ops = Operators::new(&m);
        let rot =
            Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 2.0, -0.5)), 1.1);
        let y: Vec<Point> = ops
            .positions
            .iter()
            .map(|&p| {
                let q = rot * Vector3::from(p);
                [q.x + 3.0, q.y - 1.0, q.z + 0.5]
            })
            .collect();
        for mode in [Mode::Default, Mode::Paper] {
            let mu = Mu::new(mode, m.topology(), &ops.positions, &ops.delta);
            let mut at_rest = vec![[0.0; 3]; y.len()];
            let mut moved = vec![[0.0; 3]; y.len()];
            mu.delta_hat(m.topology(), &ops.positions, &mut at_rest);
            mu.delta_hat(m.topology(), &y, &mut moved);
            for (a, b) in at_rest.iter().zip(&moved) {
                let ra = rot * Vector3::from(*a);
                assert!((ra - Vector3::from(*b)).norm() < 1e-10);
            }
        }
        let w = RingWeights::new(m.topology(), &ops.lbar);
        let mut t = vec![UnitQuaternion::identity(); y.len()];
        local_rotations(m.topology(), &w, &ops.positions, &y, &mut t);
        for ti in &t {
            assert!((ti.to_rotation_matrix().matrix() - rot.matrix()).norm() < 1e-10);
        }
    }
}
