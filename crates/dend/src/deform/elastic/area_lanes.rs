//! [`project_area`] on eight triangles at once.
//!
//! The closed form of the parent module (`σ2 > 10⁻⁴ σ1`) with Halley's
//! root of the quartic (`σ2 < 2`), each scalar replaced by eight lanes
//! (`[Real; 8]`): the same operations in the same order, so each lane's
//! result is bit-for-bit the scalar function's (Rust never contracts a
//! multiply and an add into an FMA, and `sqrt` and `/` are correctly
//! rounded in either form). A projection is a chain of about four square
//! roots and seven divisions, each waiting for the last: one triangle at
//! a time the core mostly waits; eight side by side (two independent
//! chains of 4-lane AVX2 operations) fill its pipelines. Against four
//! lanes (one chain) the local step took 15 % less time on the camel's
//! 9770 vertices and 24 % less on the hand's 1502 (best of 100 and 300,
//! one thread); sixteen were no better.
//! A lane leaves Halley's iteration when its step is short; a lane that
//! needs any other branch of the scalar function (a nearly flattened
//! triangle, `σ2 ≥ 2`, a failed Halley iteration, a non-finite input) is
//! recomputed by [`project_area`] itself, which reproduces exactly what it
//! would have done.

use super::area::project_area;
use crate::mesh::Real;

/// Triangles projected together.
pub(super) const LANES: usize = 8;

type V = [Real; LANES];

/// [`project_area`]`(f[l])` for each lane `l`; bit-for-bit equal to the
/// scalar function.
pub(super) fn project_area_lanes(f: &[[Real; 6]; LANES]) -> [[Real; 6]; LANES] {
    dend_linalg::cpu::with_avx2_fma(
        #[inline(always)]
        || project_lanes(f),
    )
}

#[inline(always)]
fn lanes(f: impl Fn(usize) -> Real) -> V {
    std::array::from_fn(f)
}

/// `x.clamp(lo, hi)` as `f64::clamp` computes it, for `lo ≤ hi`.
#[inline(always)]
fn clamp(x: Real, lo: Real, hi: Real) -> Real {
    let mut x = x;
    if x < lo {
        x = lo;
    }
    if x > hi {
        x = hi;
    }
    x
}

#[inline(always)]
fn project_lanes(f: &[[Real; 6]; LANES]) -> [[Real; 6]; LANES] {
    let col = |k: usize| lanes(|l| f[l][k]);
    let (x0, y0, z0, x1, y1, z1) = (col(0), col(1), col(2), col(3), col(4), col(5));
    // as `project_area`: FᵀF = [[a, b], [b, c]] (nalgebra's dot is
    // `(p0 q0 + p1 q1) + p2 q2`)
    let a = lanes(|l| x0[l] * x0[l] + y0[l] * y0[l] + z0[l] * z0[l]);
    let b = lanes(|l| x0[l] * x1[l] + y0[l] * y1[l] + z0[l] * z1[l]);
    let c = lanes(|l| x1[l] * x1[l] + y1[l] * y1[l] + z1[l] * z1[l]);
    let half = lanes(|l| 0.5 * (a[l] - c[l]));
    let r = lanes(|l| (half[l] * half[l] + b[l] * b[l]).sqrt());
    let l1 = lanes(|l| 0.5 * (a[l] + c[l]) + r[l]);
    let l2 = lanes(|l| {
        let q = (a[l] * c[l] - b[l] * b[l]) / l1[l];
        if l1[l] > 0.0 {
            q
        } else {
            0.0
        }
    });
    let s1 = lanes(|l| l1[l].max(0.0).sqrt());
    let s2 = lanes(|l| l2[l].max(0.0).sqrt());
    // the lanes this function computes: the closed form with Halley's
    // root from a finite start (`area_root` for σ2 < 2)
    let mut lane: [bool; LANES] = std::array::from_fn(|l| {
        s2[l] > 1e-4 * s1[l] && s2[l] < 2.0 && s1[l].is_finite() && r[l].is_finite()
    });
    let start = lanes(|l| (s1[l] / s2[l].max(1e-12)).sqrt());
    let d = halley4(&s1, &s2, &start, &mut lane);
    let g1 = lanes(|l| d[l] / s1[l]);
    let g2 = lanes(|l| 1.0 / (d[l] * s2[l]));
    // the branch on r > 0 and on the sign of `half`, as selections
    let k = lanes(|l| (g1[l] - g2[l]) / (2.0 * r[l]));
    let big = lanes(|l| {
        if half[l] >= 0.0 {
            r[l] + half[l]
        } else {
            r[l] - half[l]
        }
    });
    let small = lanes(|l| b[l] * b[l] / big[l]);
    let (pa, pc) = (
        lanes(|l| if half[l] >= 0.0 { big[l] } else { small[l] }),
        lanes(|l| if half[l] >= 0.0 { small[l] } else { big[l] }),
    );
    let pos = |l: usize| r[l] > 0.0;
    let s00 = lanes(|l| if pos(l) { g2[l] + k[l] * pa[l] } else { g2[l] });
    let s01 = lanes(|l| if pos(l) { k[l] * b[l] } else { 0.0 });
    let s11 = lanes(|l| if pos(l) { g2[l] + k[l] * pc[l] } else { g2[l] });
    std::array::from_fn(|l| {
        if !lane[l] {
            return project_area(&f[l]);
        }
        [
            x0[l] * s00[l] + x1[l] * s01[l],
            y0[l] * s00[l] + y1[l] * s01[l],
            z0[l] * s00[l] + z1[l] * s01[l],
            x0[l] * s01[l] + x1[l] * s11[l],
            y0[l] * s01[l] + y1[l] * s11[l],
            z0[l] * s01[l] + z1[l] * s11[l],
        ]
    })
}

/// `halley_root(σ1, σ2, start)` of the parent module on the lanes where
/// `lane` is set; a lane whose iteration fails (or that was not set) is
/// cleared, and its `d` is meaningless.
#[inline(always)]
fn halley4(s1: &V, s2: &V, start: &V, lane: &mut [bool; LANES]) -> V {
    let mut d = lanes(|l| clamp(start[l], 1e-6, 1e6));
    // still iterating: set lanes not done
    let mut active = *lane;
    for _ in 0..40 {
        if !active.contains(&true) {
            return d;
        }
        let d2 = lanes(|l| d[l] * d[l]);
        let p = lanes(|l| d2[l] * d2[l] - s1[l] * d2[l] * d[l] + s2[l] * d[l] - 1.0);
        let dp = lanes(|l| 4.0 * d2[l] * d[l] - 3.0 * s1[l] * d2[l] + s2[l]);
        let ddp = lanes(|l| 12.0 * d2[l] - 6.0 * s1[l] * d[l]);
        let den = lanes(|l| 2.0 * dp[l] * dp[l] - p[l] * ddp[l]);
        let next = lanes(|l| clamp(d[l] - 2.0 * p[l] * dp[l] / den[l], d[l] * 0.1, d[l] * 10.0));
        for l in 0..LANES {
            if !active[l] {
                continue;
            }
            if den[l].abs() < 1e-300 {
                (active[l], lane[l]) = (false, false);
                continue;
            }
            if (next[l] - d[l]).abs() <= 1e-4 * d[l] {
                // as `halley_root`: a root, not a point where p' = 0
                let root = p[l].abs() <= 1e-3 * d[l] * dp[l].abs();
                d[l] = next[l];
                active[l] = false;
                lane[l] = root && d[l].is_finite() && d[l] > 0.0;
                continue;
            }
            d[l] = next[l];
        }
    }
    // (not converged in 40 steps: the scalar function's `None`)
    for l in 0..LANES {
        if active[l] {
            lane[l] = false;
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The lanes through both code paths (AVX2 when the CPU has it, and
    /// the portable one) against one call of the scalar function per lane.
    fn check(f: [[Real; 6]; LANES]) {
        let expected = f.map(|fl| project_area(&fl));
        for got in [project_area_lanes(&f), project_lanes(&f)] {
            for l in 0..LANES {
                let (g, e) = (got[l].map(Real::to_bits), expected[l].map(Real::to_bits));
                assert_eq!(g, e, "lane {l}: F = {:?}", f[l]);
            }
        }
    }

    proptest! {
        /// Near rest (the iteration's case: one or two Halley steps), and
        /// stretched, shrunk or nearly collapsed triangles (more steps,
        /// the flattened path, `σ2 ≥ 2`, Halley's failures), mixed in one
        /// group.
        #[test]
        fn lanes_equal_the_scalar_function_bit_for_bit(
            raw in proptest::collection::vec(-1.0f64..1.0, 6 * LANES),
            kind in proptest::collection::vec(0usize..4, LANES),
            log_scale in proptest::collection::vec(-1.5f64..1.5, LANES),
            log_eps in proptest::collection::vec(-9.0f64..-0.5, LANES),
        ) {
            let f: [[Real; 6]; LANES] = std::array::from_fn(|l| {
                let e: [Real; 6] = std::array::from_fn(|k| raw[6 * l + k]);
                match kind[l] {
                    // a rotation-like F (orthonormal columns) perturbed
                    0 => {
                        let u = nalgebra::Vector3::new(e[0], e[1], e[2] + 2.0).normalize();
                        let w = nalgebra::Vector3::new(e[3], e[4], e[5]);
                        let v = (w - u * u.dot(&w) + nalgebra::Vector3::x() * 1e-3).normalize();
                        let t = 0.05 * log_eps[l].exp();
                        [u[0] + t * e[3], u[1], u[2], v[0], v[1] + t * e[0], v[2]]
                    }
                    // scaled anywhere in 10^±1.5
                    1 | 2 => e.map(|x| x * 10f64.powf(log_scale[l])),
                    // a second column nearly a multiple of the first
                    _ => {
                        let eps = 10f64.powf(log_eps[l]);
                        [e[0], e[1], e[2], 0.7 * e[0] + eps * e[3], 0.7 * e[1] + eps * e[4], 0.7 * e[2] + eps * e[5]]
                    }
                }
            });
            check(f);
        }
    }

    #[test]
    fn special_lanes_fall_back_like_the_scalar_function() {
        check([
            [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],   // the identity
            [0.0; 6],                         // collapsed to a point
            [3.0, 0.0, 0.0, 0.0, 2.5, 0.0],   // σ2 ≥ 2
            [1.0, 2.0, 3.0, 2.0, 4.0, 6.0],   // collapsed to a segment
            super::super::area::HALLEY_STALL, // Halley stalls where p' = 0
            [2.0, 0.0, 0.0, 0.0, 0.5, 0.0],
            [1.0, 0.0, 0.0, 0.0, 1e-9, 0.0],
            [0.6, 0.8, 0.0, 0.0, 0.0, 1.0],
        ]);
    }
}
