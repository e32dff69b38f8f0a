//! The area term of the elastic energy (E3 in the parent module):
//! per triangle its deformation gradient `F_t` and the nearest matrix with
//! singular values `d, 1/d` (Projective Dynamics' area constraint, Bouaziz
//! et al. 2014).

use nalgebra::{Matrix2, Vector2, Vector3};

use crate::mesh::{Point, Real};

/// One triangle of the area term: its vertices, `B = D_m⁻¹` (the rest
/// edges in an orthonormal frame of the rest triangle, inverted) and
/// `k_a a_t`.
#[derive(Debug, Clone, Copy)]
pub(super) struct AreaElement {
    pub(super) v: [u32; 3],
    pub(super) b: Matrix2<Real>,
    pub(super) weight: Real,
}

impl AreaElement {
    /// Each corner's coefficients `(k0, k1)` in the columns of
    /// `F = [y1 − y0, y2 − y0] B`: column `c` is `Σ_v k_vc y_v`, so
    /// `k_1 = B_0·`, `k_2 = B_1·` and `k_0 = −(B_0· + B_1·)`.
    pub(super) fn corners(&self) -> [[Real; 2]; 3] {
        let b = &self.b;
        [
            [-(b[(0, 0)] + b[(1, 0)]), -(b[(0, 1)] + b[(1, 1)])],
            [b[(0, 0)], b[(0, 1)]],
            [b[(1, 0)], b[(1, 1)]],
        ]
    }
}

/// The area element of triangle `t` on positions `x`, or `None` when it
/// is degenerate.
pub(super) fn area_element(x: &[Point], t: [u32; 3], ka: Real) -> Option<AreaElement> {
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

/// The area term's forces on each vertex, gathered: `a_t P_t Bᵀ` scattered
/// onto triangle `t` (`+` its first column on `v1`, `+` the second on
/// `v2`, `−` both on `v0`) is, for the vertex at one corner,
/// `k0 P_t[:, 0] + k1 P_t[:, 1]` with `(k0, k1)` fixed by the rest
/// triangle. Stored per vertex (CSR, triangles in order), so that the
/// residual sums each vertex's forces on its own: in parallel, and in the
/// same order for any thread count.
#[derive(Debug, Clone, Default)]
pub(super) struct AreaForces {
    /// Incidences of vertex `v`: `ptr[v]..ptr[v + 1]`.
    ptr: Vec<usize>,
    /// The area element (index into the projections).
    el: Vec<u32>,
    /// `(k0, k1)` of the incidence.
    k: Vec<[Real; 2]>,
}

impl AreaForces {
    /// The incidences of `n` vertices in the elements `area`.
    pub(super) fn new(n: usize, area: &[AreaElement]) -> Self {
        let mut count = vec![0usize; n + 1];
        for el in area {
            for &v in &el.v {
                count[v as usize + 1] += 1;
            }
        }
        for v in 0..n {
            count[v + 1] += count[v];
        }
        let ptr = count.clone();
        let mut next = count;
        let total = ptr[n];
        let (mut els, mut k) = (vec![0u32; total], vec![[0.0; 2]; total]);
        for (t, el) in area.iter().enumerate() {
            // column c of a_t P Bᵀ is a_t (P[:, 0] B[c, 0] + P[:, 1] B[c, 1]):
            // the corners' coefficients of F, weighted
            let w = el.weight;
            for (&v, kc) in el.v.iter().zip(el.corners()) {
                let slot = &mut next[v as usize];
                els[*slot] = t as u32;
                k[*slot] = [w * kc[0], w * kc[1]];
                *slot += 1;
            }
        }
        AreaForces { ptr, el: els, k }
    }

    /// `Σ_t k0 P_t[:, 0] + k1 P_t[:, 1]` over the triangles at `v`, added
    /// to `acc`.
    #[inline]
    pub(super) fn add(&self, v: usize, proj: &[[Real; 6]], acc: &mut Point) {
        for s in self.ptr[v]..self.ptr[v + 1] {
            let p = &proj[self.el[s] as usize];
            let [k0, k1] = self.k[s];
            for a in 0..3 {
                acc[a] += k0 * p[a] + k1 * p[3 + a];
            }
        }
    }

    /// Memory held, in bytes.
    pub(super) fn memory_bytes(&self) -> usize {
        self.ptr.len() * 8 + self.el.len() * 4 + self.k.len() * 16
    }
}

/// `F = [y1 − y0, y2 − y0] B`, column-major `[F00, F10, F20, F01, F11, F21]`.
pub(super) fn gradient(y: &[Point], el: &AreaElement) -> [Real; 6] {
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
///
/// When `σ2 > 10⁻⁴ σ1` (every triangle that is not nearly flattened),
/// `U = F V Σ⁻¹` gives `P = F S` with the 2×2
/// `S = V diag(d/σ1, 1/(d σ2)) Vᵀ = g2 I + (g1 − g2) v1 v1ᵀ`, and
/// `v1 v1ᵀ = (FᵀF − λ2 I) / (λ1 − λ2)` in closed form: no eigenvector and
/// no `U` is built (the local step's largest cost before).
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
    let s1 = l1.max(0.0).sqrt();
    let s2 = l2.max(0.0).sqrt();
    if s2 > 1e-4 * s1 {
        let d = area_root(s1, s2);
        let (g1, g2) = (d / s1, 1.0 / (d * s2));
        // λ1 − λ2 = 2r; FᵀF − λ2 I = [[r + half, b], [b, r − half]], the
        // smaller diagonal entry as b² / (the larger) against cancellation
        let (s00, s01, s11) = if r > 0.0 {
            let k = (g1 - g2) / (2.0 * r);
            let (pa, pc) = if half >= 0.0 {
                (r + half, b * b / (r + half))
            } else {
                (b * b / (r - half), r - half)
            };
            (g2 + k * pa, k * b, g2 + k * pc)
        } else {
            (g2, 0.0, g2)
        };
        let p0 = c0 * s00 + c1 * s01;
        let p1 = c0 * s01 + c1 * s11;
        return [p0[0], p0[1], p0[2], p1[0], p1[1], p1[2]];
    }
    project_area_flat(f, (a, b, c), l1, (s1, s2))
}

/// [`project_area`] of a (nearly) flattened `F`, `σ2 ≤ 10⁻⁴ σ1`: `U`
/// built column by column, the second orthogonalised against the first
/// (or any unit vector orthogonal to it when `σ2` vanishes).
/// `abc` is `FᵀF = [[a, b], [b, c]]`, `l1` its larger eigenvalue.
fn project_area_flat(
    f: &[Real; 6],
    (a, b, c): (Real, Real, Real),
    l1: Real,
    (s1, s2): (Real, Real),
) -> [Real; 6] {
    let c0 = Vector3::new(f[0], f[1], f[2]);
    let c1 = Vector3::new(f[3], f[4], f[5]);
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

/// `argmin_{d > 0} (d − σ1)² + (1/d − σ2)²`, a root of the stationarity
/// quartic `p(d) = d⁴ − σ1 d³ + σ2 d − 1 = d³ f'(d) / 2`, by Halley's
/// method from `√(σ1/σ2)` (exact when `σ1 = σ2`, its error second order in
/// `σ1 − 1, σ2 − 1`: near rest one step).
///
/// For `σ2 < 2`, `f'' = 2 + 6/d⁴ − 4σ2/d³ > 0` on all of `d > 0`
/// (`d⁴ f''` is least at `d³ = σ2/2`, where it is `6 − 6d⁴ > 0`): `f` is
/// strictly convex and its one stationary point is the minimum. Halley's
/// method on `p` is not globally convergent even then (from `√(σ1/σ2)` it
/// can walk to where `p' = 0` and stall there: `σ1 = 20.5, σ2 = 0.23`
/// stalled at `d = 0.062` against the minimum at `20.46`), so its root is
/// checked ([`halley_root`]) and, failing that, [`convex_root`] finds it
/// inside a bracket. Otherwise (`σ2 ≥ 2`) it is the general search: a
/// local minimum from `√(σ1/σ2)`, else from `σ1`, and the best of those
/// and `d = 1`.
pub(super) fn area_root(s1: Real, s2: Real) -> Real {
    let start = (s1 / s2.max(1e-12)).sqrt();
    if s2 < 2.0 {
        return halley_root(s1, s2, start).unwrap_or_else(|| convex_root(s1, s2, start));
    }
    let f = |d: Real| (d - s1) * (d - s1) + (1.0 / d - s2) * (1.0 / d - s2);
    let local_min = |d: Real| curvature(s2, d) > 0.0;
    let mut best = (f(1.0), 1.0);
    let first = halley_root(s1, s2, start).filter(|&d| local_min(d));
    let candidates = match first {
        Some(d) => [Some(d), None],
        None => [
            None,
            halley_root(s1, s2, s1.max(1e-6)).filter(|&d| local_min(d)),
        ],
    };
    for d in candidates.into_iter().flatten() {
        if f(d) < best.0 {
            best = (f(d), d);
        }
    }
    best.1
}

/// `f''(d) = 2 + 6/d⁴ − 4σ2/d³` of `f(d) = (d − σ1)² + (1/d − σ2)²`
/// ([`area_root`]; it does not depend on `σ1`).
pub(super) fn curvature(s2: Real, d: Real) -> Real {
    let id = 1.0 / d;
    let id3 = id * id * id;
    2.0 + 6.0 * id3 * id - 4.0 * s2 * id3
}

/// A positive root of `p(d) = d⁴ − σ1 d³ + σ2 d − 1` by Halley's method
/// (steps kept within a factor 10), or `None` if it does not converge in
/// 40 steps or stops where `p` is not zero (a short Halley step also
/// happens where `p' = 0`, far from any root). Convergence is cubic: once
/// a step is below `10⁻⁴ d` next to a root the error left is about `10⁻¹²`
/// relative, and the area energy, stationary in `d`, is exact to rounding.
fn halley_root(s1: Real, s2: Real, start: Real) -> Option<Real> {
    let mut d: Real = start.clamp(1e-6, 1e6);
    for _ in 0..40 {
        let d2 = d * d;
        let p = d2 * d2 - s1 * d2 * d + s2 * d - 1.0;
        let dp = 4.0 * d2 * d - 3.0 * s1 * d2 + s2;
        let ddp = 12.0 * d2 - 6.0 * s1 * d;
        let den = 2.0 * dp * dp - p * ddp;
        if den.abs() < 1e-300 {
            return None;
        }
        let next = (d - 2.0 * p * dp / den).clamp(d * 0.1, d * 10.0);
        let done = (next - d).abs() <= 1e-4 * d;
        if done {
            // next to a root a Newton step is as short; where p' = 0 it is
            // not (there p/p' is large while Halley's step 2pp'/(2p'² − pp'')
            // vanishes)
            let root = p.abs() <= 1e-3 * d * dp.abs();
            d = next;
            return (root && d.is_finite() && d > 0.0).then_some(d);
        }
        d = next;
    }
    None
}

/// The one minimiser of the strictly convex `f(d) = (d − σ1)² + (1/d − σ2)²`
/// (`σ2 < 2`, see [`area_root`]): Newton's method on `f'` from `start`,
/// kept inside a bracket `[lo, hi]` with `f'(lo) < 0 < f'(hi)` and
/// bisected when a step leaves it. `lo = 10⁻⁸` (there
/// `f' = 2(d − σ1) − 2(1/d − σ2)/d² < 0` for `σ2 < 2`) and
/// `hi = max(σ1, 1) + 1` (`d − σ1 ≥ 1 > (1/d − σ2)/d²`).
fn convex_root(s1: Real, s2: Real, start: Real) -> Real {
    let fp = |d: Real| {
        let id = 1.0 / d;
        2.0 * (d - s1) - 2.0 * (id - s2) * id * id
    };
    let (mut lo, mut hi): (Real, Real) = (1e-8, s1.max(1.0) + 1.0);
    let mut d = if start > lo && start < hi {
        start
    } else {
        0.5 * (lo + hi)
    };
    for _ in 0..200 {
        let g = fp(d);
        if g < 0.0 {
            lo = d;
        } else {
            hi = d;
        }
        let newton = d - g / curvature(s2, d);
        let next = if newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - d).abs() <= 1e-14 * d || hi - lo <= 1e-14 * hi {
            return next;
        }
        d = next;
    }
    d
}

/// A deformation gradient (σ 20.46, 0.2345) on which Halley's method on
/// the quartic reaches `p' = 0` (found by a random search): a case every
/// projection must handle.
#[cfg(test)]
pub(super) const HALLEY_STALL: [Real; 6] = [
    13.815142394995833,
    -7.084317433370278,
    8.774436662673722,
    7.925781520741228,
    -3.7823380224559817,
    4.8495640365943995,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stretched_nearly_collapsed_triangle_projects_to_the_nearest() {
        // Halley's stalling case: the projection's distance is the least
        // over d, as the independent search says
        let f = HALLEY_STALL;
        let m: nalgebra::Matrix3x2<Real> =
            nalgebra::Matrix3x2::new(f[0], f[3], f[1], f[4], f[2], f[5]);
        let sv = m.singular_values();
        let (s1, s2) = (sv[0].max(sv[1]), sv[0].min(sv[1]));
        let d = area_root_by_search(s1, s2);
        let best = (d - s1).powi(2) + (1.0 / d - s2).powi(2);
        let p = project_area(&f);
        let dist: Real = f.iter().zip(&p).map(|(a, b)| (a - b).powi(2)).sum();
        assert!(
            (dist - best).abs() <= 1e-9 * (1.0 + best),
            "|F − P|² {dist}, the nearest {best}"
        );
    }

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

    /// `d` minimising `(d − σ1)² + (1/d − σ2)²`, found independently: the
    /// best point of a log grid, refined by golden-section search.
    fn area_root_by_search(s1: Real, s2: Real) -> Real {
        let g = |d: Real| (d - s1).powi(2) + (1.0 / d - s2).powi(2);
        let grid: Vec<Real> = (0..4000)
            .map(|k| (k as Real * 0.005 - 10.0).exp())
            .collect();
        let k = (1..grid.len() - 1)
            .min_by(|&i, &j| g(grid[i]).total_cmp(&g(grid[j])))
            .expect("a non-empty grid");
        let (mut lo, mut hi) = (grid[k - 1], grid[k + 1]);
        let phi = (5.0_f64.sqrt() - 1.0) / 2.0;
        for _ in 0..200 {
            let (x1, x2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
            if g(x1) < g(x2) {
                hi = x2;
            } else {
                lo = x1;
            }
        }
        0.5 * (lo + hi)
    }

    proptest::proptest! {
        /// The closed form `P = F S` against the flattened-triangle path
        /// (which builds `U` column by column) where `λ1 − λ2` is tiny or
        /// zero, the case the closed form divides by: a random rotation and
        /// right factor `V`, `σ2 = σ1 (1 − ε)`. Below `σ = 2` only: beyond,
        /// equal singular values have two minimising `d` (`d` and `1/d`
        /// with the directions swapped) and `P` is not a function of `F`.
        #[test]
        fn the_closed_form_matches_the_column_path_at_near_equal_singular_values(
            angles in proptest::array::uniform3(-3.0..3.0f64),
            phi in -3.0..3.0f64,
            s1 in 0.2..1.95f64,
            log_eps in -16.0..-2.0f64,
        ) {
            let eps = if log_eps < -15.5 { 0.0 } else { 10f64.powf(log_eps) };
            let s2 = s1 * (1.0 - eps);
            let r = nalgebra::Rotation3::from_euler_angles(angles[0], angles[1], angles[2]);
            let u = r.matrix().columns(0, 2).into_owned();
            let v = nalgebra::Rotation2::new(phi).into_inner();
            let m = u * Matrix2::new(s1, 0.0, 0.0, s2) * v.transpose();
            let f = [m[(0, 0)], m[(1, 0)], m[(2, 0)], m[(0, 1)], m[(1, 1)], m[(2, 1)]];
            let c0 = Vector3::new(f[0], f[1], f[2]);
            let c1 = Vector3::new(f[3], f[4], f[5]);
            let (a, b, c) = (c0.dot(&c0), c0.dot(&c1), c1.dot(&c1));
            let l1 = 0.5 * (a + c) + (0.25 * (a - c) * (a - c) + b * b).sqrt();
            let want = project_area_flat(&f, (a, b, c), l1, (s1, s2));
            let got = project_area(&f);
            for k in 0..6 {
                proptest::prop_assert!(
                    (got[k] - want[k]).abs() < 1e-9 * (1.0 + s1),
                    "ε {}: got {:?}, want {:?}", eps, got, want
                );
            }
        }


        /// Stretched triangles, `σ1` up to 40 with `σ2 < 2` (where `f` is
        /// convex): `d` against the independent search. Halley's method on
        /// the quartic from `√(σ1/σ2)` once stalled where `p' = 0` here
        /// (`σ1 = 20.5, σ2 = 0.23`: `d = 0.062` against `20.46`).
        #[test]
        fn the_root_is_the_minimum_for_stretched_triangles(
            s1 in 1.0..40.0f64,
            s2_share in 0.001..1.0f64,
        ) {
            let s2 = (s1 * s2_share).min(1.99);
            let (got, want) = (area_root(s1, s2), area_root_by_search(s1, s2));
            let g = |d: Real| (d - s1).powi(2) + (1.0 / d - s2).powi(2);
            proptest::prop_assert!(
                (got - want).abs() <= 1e-6 * want && g(got) <= g(want) * (1.0 + 1e-9) + 1e-12,
                "σ {} {}: d {} (f {}), the search's {} (f {})", s1, s2, got, g(got), want, g(want)
            );
        }

        /// Against an independent computation: nalgebra's SVD of a random
        /// 3×2 matrix and `d` by a direct search. The matrices are scaled
        /// by `10^[-1.5, 1.5]` (triangles shrunk or stretched up to 30×) and
        /// a third of them have a second column close to a multiple of the
        /// first (triangles nearly collapsed to a segment): `σ1 = 20.5,
        /// σ2 = 0.23` once sent Halley's method on the quartic to a point
        /// where `p' = 0`, and the projection went far from the nearest.
        #[test]
        fn the_area_projection_matches_an_svd_and_a_direct_search(
            raw in proptest::array::uniform6(-1.5..1.5f64),
            log_scale in -1.5..1.5f64,
            slant in proptest::option::weighted(0.33, (-2.0..2.0f64, -3.0..-0.5f64)),
        ) {
            let scale = 10f64.powf(log_scale);
            let mut f = raw.map(|x| x * scale);
            if let Some((t, log_eps)) = slant {
                let eps = 10f64.powf(log_eps);
                for k in 0..3 {
                    f[3 + k] = t * f[k] + eps * f[3 + k];
                }
            }
            let m = nalgebra::Matrix3x2::new(f[0], f[3], f[1], f[4], f[2], f[5]);
            let svd = m.svd(true, true);
            let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
            let (s1, s2) = (svd.singular_values[0], svd.singular_values[1]);
            // near-equal or vanishing singular values make the subspaces
            // (and the independent reference) ill-defined
            proptest::prop_assume!(s1 - s2 > 1e-3 * s1 && s2 > 1e-3 * s1);
            let d = area_root_by_search(s1, s2);
            let want = u.columns(0, 2) * nalgebra::Matrix2::new(d, 0.0, 0.0, 1.0 / d) * vt;
            let got = project_area(&f);
            let cells = [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1)];
            for (k, (r, c)) in cells.into_iter().enumerate() {
                proptest::prop_assert!(
                    (got[k] - want[(r, c)]).abs() < 1e-7 * (1.0 + want.abs().max()),
                    "F {} σ {} {}: got {:?}, want {}", m, s1, s2, got, want
                );
            }
        }
    }
}
