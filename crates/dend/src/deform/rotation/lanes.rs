//! [`fit_rotation_quat`] on four covariances at once.
//!
//! The Newton iteration of the parent module, with each scalar replaced by
//! four lanes (`[Real; 4]`): the same operations in the same order, so each
//! lane's result is bit-for-bit the scalar function's (Rust never contracts
//! a multiply and an add into an FMA, so no lane rounds differently). With
//! AVX2 the lanes are one 256-bit register and a step of four vertices costs
//! about what one scalar step did. A lane leaves the group when its Newton
//! step is below the convergence threshold; a lane that needs any other
//! branch of the scalar iteration (an indefinite Hessian, a clamped step, a
//! non-finite or zero covariance, no convergence) is recomputed by the
//! scalar function from its original guess, which reproduces exactly what
//! the scalar iteration would have done.

use nalgebra::{Matrix3, Quaternion, UnitQuaternion};

use super::{fit_rotation_quat, CONVERGED_STEP, MAX_NEWTON};
use crate::mesh::Real;

/// Covariances fitted together.
pub const LANES: usize = 4;

type V4 = [Real; LANES];

/// [`fit_rotation_quat`]`(a[l], q[l])` for each lane `l`, written back to
/// `q`; bit-for-bit equal to the scalar function.
pub fn fit_rotation_quat4(a: &[Matrix3<Real>; LANES], q: &mut [UnitQuaternion<Real>; LANES]) {
    dend_linalg::cpu::with_avx2_fma(
        #[inline(always)]
        || fit4(a, q),
    )
}

/// What happens to a lane.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Lane {
    /// Still stepping.
    Newton,
    /// Converged: `q` holds the result.
    Done,
    /// Recomputed by the scalar function.
    Scalar,
}

#[inline(always)]
fn map4(f: impl Fn(usize) -> Real) -> V4 {
    [f(0), f(1), f(2), f(3)]
}

#[inline(always)]
fn fit4(a: &[Matrix3<Real>; LANES], q_out: &mut [UnitQuaternion<Real>; LANES]) {
    let guess = *q_out;
    let mut state = [Lane::Newton; LANES];
    // a[i][j] per lane, and the lanes that the scalar function treats apart
    let mut am = [[[0.0; LANES]; 3]; 3];
    for (l, al) in a.iter().enumerate() {
        let (mut finite, mut zero) = (true, true);
        for i in 0..3 {
            for j in 0..3 {
                let v = al[(i, j)];
                finite &= v.is_finite();
                zero &= v == 0.0;
                am[i][j][l] = v;
            }
        }
        if !finite || zero {
            state[l] = Lane::Scalar;
        }
    }
    let mut q: [V4; 4] = [
        map4(|l| guess[l].quaternion().w),
        map4(|l| guess[l].quaternion().i),
        map4(|l| guess[l].quaternion().j),
        map4(|l| guess[l].quaternion().k),
    ];
    for _ in 0..MAX_NEWTON {
        if !state.contains(&Lane::Newton) {
            break;
        }
        let Step {
            q: qn,
            angle2,
            definite,
            finite,
        } = newton_step(&am, &q);
        const MAX_STEP: Real = std::f64::consts::FRAC_PI_2;
        for l in 0..LANES {
            if state[l] != Lane::Newton {
                continue;
            }
            let newton = definite[l] && finite[l];
            if !newton || angle2[l] > MAX_STEP * MAX_STEP {
                state[l] = Lane::Scalar;
                continue;
            }
            for k in 0..4 {
                q[k][l] = qn[k][l];
            }
            if angle2[l] < CONVERGED_STEP * CONVERGED_STEP {
                state[l] = Lane::Done;
            }
        }
    }
    for l in 0..LANES {
        q_out[l] = match state[l] {
            Lane::Done => {
                UnitQuaternion::new_unchecked(Quaternion::new(q[0][l], q[1][l], q[2][l], q[3][l]))
            }
            Lane::Newton | Lane::Scalar => fit_rotation_quat(&a[l], &guess[l]),
        };
    }
}

/// One Newton step of the four lanes, straight-line arithmetic (no branch,
/// so that it vectorises): the stepped quaternions, the squared step, and
/// whether `H` was positive definite and the step finite.
struct Step {
    q: [V4; 4],
    angle2: V4,
    definite: [bool; LANES],
    finite: [bool; LANES],
}

#[inline(always)]
fn newton_step(am: &[[V4; 3]; 3], q: &[V4; 4]) -> Step {
    // R(q) rows, as in `quat_to_rows`
    let [w, x, y, z] = *q;
    let xx = map4(|l| x[l] * x[l]);
    let yy = map4(|l| y[l] * y[l]);
    let zz = map4(|l| z[l] * z[l]);
    let xy = map4(|l| x[l] * y[l]);
    let xz = map4(|l| x[l] * z[l]);
    let yz = map4(|l| y[l] * z[l]);
    let wx = map4(|l| w[l] * x[l]);
    let wy = map4(|l| w[l] * y[l]);
    let wz = map4(|l| w[l] * z[l]);
    let r = [
        [
            map4(|l| 1.0 - 2.0 * (yy[l] + zz[l])),
            map4(|l| 2.0 * (xy[l] - wz[l])),
            map4(|l| 2.0 * (xz[l] + wy[l])),
        ],
        [
            map4(|l| 2.0 * (xy[l] + wz[l])),
            map4(|l| 1.0 - 2.0 * (xx[l] + zz[l])),
            map4(|l| 2.0 * (yz[l] - wx[l])),
        ],
        [
            map4(|l| 2.0 * (xz[l] - wy[l])),
            map4(|l| 2.0 * (yz[l] + wx[l])),
            map4(|l| 1.0 - 2.0 * (xx[l] + yy[l])),
        ],
    ];
    // B = A Rᵀ
    let b: [[V4; 3]; 3] = std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            map4(|l| am[i][0][l] * r[j][0][l] + am[i][1][l] * r[j][1][l] + am[i][2][l] * r[j][2][l])
        })
    });
    let g = [
        map4(|l| b[2][1][l] - b[1][2][l]),
        map4(|l| b[0][2][l] - b[2][0][l]),
        map4(|l| b[1][0][l] - b[0][1][l]),
    ];
    let tr = map4(|l| b[0][0][l] + b[1][1][l] + b[2][2][l]);
    let h00 = map4(|l| tr[l] - b[0][0][l]);
    let h11 = map4(|l| tr[l] - b[1][1][l]);
    let h22 = map4(|l| tr[l] - b[2][2][l]);
    let h01 = map4(|l| -0.5 * (b[0][1][l] + b[1][0][l]));
    let h02 = map4(|l| -0.5 * (b[0][2][l] + b[2][0][l]));
    let h12 = map4(|l| -0.5 * (b[1][2][l] + b[2][1][l]));
    // `solve_spd3`
    let c00 = map4(|l| h11[l] * h22[l] - h12[l] * h12[l]);
    let c01 = map4(|l| h02[l] * h12[l] - h01[l] * h22[l]);
    let c02 = map4(|l| h01[l] * h12[l] - h02[l] * h11[l]);
    let c11 = map4(|l| h00[l] * h22[l] - h02[l] * h02[l]);
    let c12 = map4(|l| h01[l] * h02[l] - h00[l] * h12[l]);
    let c22 = map4(|l| h00[l] * h11[l] - h01[l] * h01[l]);
    let det = map4(|l| h00[l] * c00[l] + h01[l] * c01[l] + h02[l] * c02[l]);
    let inv = map4(|l| 1.0 / det[l]);
    let om = [
        map4(|l| (c00[l] * g[0][l] + c01[l] * g[1][l] + c02[l] * g[2][l]) * inv[l]),
        map4(|l| (c01[l] * g[0][l] + c11[l] * g[1][l] + c12[l] * g[2][l]) * inv[l]),
        map4(|l| (c02[l] * g[0][l] + c12[l] * g[1][l] + c22[l] * g[2][l]) * inv[l]),
    ];
    let angle2 = map4(|l| om[0][l] * om[0][l] + om[1][l] * om[1][l] + om[2][l] * om[2][l]);
    // `retract`
    let half = [
        map4(|l| 0.5 * om[0][l]),
        map4(|l| 0.5 * om[1][l]),
        map4(|l| 0.5 * om[2][l]),
    ];
    let [ha, hb, hc] = half;
    let p = [
        map4(|l| w[l] - ha[l] * x[l] - hb[l] * y[l] - hc[l] * z[l]),
        map4(|l| x[l] + ha[l] * w[l] + hb[l] * z[l] - hc[l] * y[l]),
        map4(|l| y[l] + hb[l] * w[l] + hc[l] * x[l] - ha[l] * z[l]),
        map4(|l| z[l] + hc[l] * w[l] + ha[l] * y[l] - hb[l] * x[l]),
    ];
    let norm = map4(|l| {
        1.0 / (p[0][l] * p[0][l] + p[1][l] * p[1][l] + p[2][l] * p[2][l] + p[3][l] * p[3][l]).sqrt()
    });
    Step {
        q: [
            map4(|l| p[0][l] * norm[l]),
            map4(|l| p[1][l] * norm[l]),
            map4(|l| p[2][l] * norm[l]),
            map4(|l| p[3][l] * norm[l]),
        ],
        angle2,
        definite: std::array::from_fn(|l| h00[l] > 0.0 && c22[l] > 0.0 && det[l] > 0.0),
        finite: std::array::from_fn(|l| {
            om[0][l].is_finite() && om[1][l].is_finite() && om[2][l].is_finite()
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit, Vector3};
    use proptest::prelude::*;

    fn quat(axis: &[f64], angle: f64) -> UnitQuaternion<f64> {
        let ax = Vector3::new(axis[0], axis[1], axis[2] + 1e-3);
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_axis_angle(
            &Unit::new_normalize(ax),
            angle,
        ))
    }

    /// Four lanes through both code paths (AVX2 when the CPU has it, and
    /// the portable one) against four calls of the scalar function.
    fn check(a: [Matrix3<f64>; LANES], guess: [UnitQuaternion<f64>; LANES]) {
        let expected: Vec<_> = (0..LANES)
            .map(|l| fit_rotation_quat(&a[l], &guess[l]))
            .collect();
        let mut dispatched = guess;
        fit_rotation_quat4(&a, &mut dispatched);
        let mut portable = guess;
        fit4(&a, &mut portable);
        for l in 0..LANES {
            for got in [dispatched[l], portable[l]] {
                assert_eq!(
                    got.quaternion().coords,
                    expected[l].quaternion().coords,
                    "lane {l}: A = {}",
                    a[l]
                );
            }
        }
    }

    proptest! {
        /// Near the maximum (the DEND case: a guess a few degrees off) and
        /// far from it (arbitrary covariances and guesses: clamped steps,
        /// indefinite Hessians, the SVD fallback), mixed in one group.
        #[test]
        fn lanes_equal_the_scalar_function_bit_for_bit(
            e in proptest::collection::vec(-3.0f64..3.0, 36),
            axes in proptest::collection::vec(-1.0f64..1.0, 12),
            angles in proptest::collection::vec(-3.1f64..3.1, 4),
            near in proptest::collection::vec(any::<bool>(), 4),
        ) {
            let mut a = [Matrix3::zeros(); LANES];
            let mut guess = [UnitQuaternion::identity(); LANES];
            for l in 0..LANES {
                let axis = &axes[3 * l..3 * l + 3];
                let m = Matrix3::from_row_slice(&e[9 * l..9 * l + 9]);
                if near[l] {
                    // A = T S with S symmetric positive definite: the
                    // maximum is T; the guess is 0.05 rad away
                    let s = m * m.transpose() + Matrix3::identity();
                    let t = quat(axis, angles[l]);
                    a[l] = t.to_rotation_matrix().into_inner() * s;
                    guess[l] = quat(&[axis[1], axis[2], axis[0]], 0.05) * t;
                } else {
                    a[l] = m;
                    guess[l] = quat(axis, angles[l]);
                }
            }
            check(a, guess);
        }
    }

    #[test]
    fn special_lanes_fall_back_like_the_scalar_function() {
        let g = quat(&[0.3, -0.2, 0.9], 0.7);
        let rot = g.to_rotation_matrix().into_inner();
        let a = [
            Matrix3::zeros(),                                                // keeps the guess
            Matrix3::from_element(f64::NAN),                                 // identity
            rot * Matrix3::new(2.0, 0.1, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0, 0.5), // Newton
            -Matrix3::identity(), // a saddle for the Newton model
        ];
        check(a, [g; LANES]);
    }
}
