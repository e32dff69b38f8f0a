//! The elastic energy's residual `g(R, P) − Q Y` (the global step's right
//! side; parent module docs).

use nalgebra::UnitQuaternion;
use rayon::prelude::*;

use super::{ElasticOps, ElasticSet, PARALLEL_MIN};
use crate::mesh::{Point, Real};
use crate::operators::Operators;

impl ElasticOps {
    /// `out = g(R, P) − Q Y` (module docs), `#V`: the negative half-gradient
    /// of `E` in `Y` at fixed `R` and `P`. `t` (`#V`) and `rm` (`#V`, the
    /// rotations as matrices) are scratch.
    ///
    /// Every vertex's row is summed on its own (the spokes into `v`, and
    /// the area forces of its triangles, gathered: [`super::AreaForces`]),
    /// so the rows run in parallel and in the same order for any thread
    /// count; only the spokes' far rotations `R_j` are read per spoke.
    #[allow(clippy::too_many_arguments)]
    pub fn residual(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        y: &[Point],
        rot: &[UnitQuaternion<Real>],
        proj: &[[Real; 6]],
        (t, rm): (&mut [Point], &mut [[Real; 4]]),
        out: &mut [Point],
    ) {
        let n = y.len();
        // R_i as a matrix (zero where the rows are dropped) and
        // t_i = [i free] R_i δ_i
        let matrices = |(i, (r, ti)): (usize, (&mut [Real; 4], &mut Point))| {
            *r = if set.free[i] {
                let q = rot[i].quaternion();
                [q.w, q.i, q.j, q.k]
            } else {
                [0.0; 4]
            };
            *ti = if self.b[i] > 0.0 {
                rotate(r, ops.delta[i])
            } else {
                [0.0; 3]
            };
        };
        if n >= PARALLEL_MIN {
            rm.par_iter_mut()
                .zip(t.par_iter_mut())
                .enumerate()
                .for_each(matrices);
        } else {
            rm.iter_mut()
                .zip(t.iter_mut())
                .enumerate()
                .for_each(matrices);
        }
        let (t, rm): (&[Point], &[[Real; 4]]) = (t, rm);
        // out = kbl Lbar t − Q Y − Σ_j c_vj ([v free] R_v + [j free] R_j) e_vj
        //       + Σ_t a_t (P_t Bᵀ) at v
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
            // c is symmetric and e_jv = −e_vj: the spokes into v gather too;
            // R_v's part is R_v Σ_j c_vj e_vj
            let own = rotate(&rm[v], self.ce[v]);
            for a in 0..3 {
                acc[a] -= own[a];
            }
            for s in self.ptr[v]..self.ptr[v + 1] {
                let j = self.nbr[s] as usize;
                let re = rotate(&rm[j], self.e[s]);
                for a in 0..3 {
                    acc[a] -= self.c[s] * re[a];
                }
            }
            self.area_forces.add(v, proj, &mut acc);
            *o = acc;
        };
        if n >= PARALLEL_MIN {
            out.par_iter_mut().enumerate().for_each(row);
        } else {
            out.iter_mut().enumerate().for_each(row);
        }
    }
}

/// `R v` for the quaternion `q = (w, x, y, z)`:
/// `(w² − |u|²) v + 2 (u·v) u + 2 w (u × v)`, `u = (x, y, z)`: the
/// rotation of a unit quaternion, and 0 for `q = 0`.
#[inline(always)]
fn rotate(q: &[Real; 4], v: Point) -> Point {
    let [w, x, y, z] = *q;
    let s = w * w - (x * x + y * y + z * z);
    let d = 2.0 * (x * v[0] + y * v[1] + z * v[2]);
    let w2 = 2.0 * w;
    [
        s * v[0] + d * x + w2 * (y * v[2] - z * v[1]),
        s * v[1] + d * y + w2 * (z * v[0] - x * v[2]),
        s * v[2] + d * z + w2 * (x * v[1] - y * v[0]),
    ]
}

#[cfg(test)]
mod tests {
    use super::rotate;
    use nalgebra::{UnitQuaternion, Vector3};

    /// `rotate` is nalgebra's rotation for unit quaternions, and 0 for the
    /// zero quaternion (a vertex whose rows are dropped).
    #[test]
    fn rotate_is_the_quaternions_rotation_and_zero_for_zero() {
        let v = [0.3, -1.7, 2.2];
        for (axis, angle) in [
            ([1.0, 2.0, -0.5], 0.7),
            ([0.0, 0.0, 1.0], 3.0),
            ([-1.0, 0.2, 0.1], -2.4),
        ] {
            let q = UnitQuaternion::from_axis_angle(
                &nalgebra::Unit::new_normalize(Vector3::from(axis)),
                angle,
            );
            let c = q.quaternion();
            let got = rotate(&[c.w, c.i, c.j, c.k], v);
            let want = q * Vector3::from(v);
            for a in 0..3 {
                assert!((got[a] - want[a]).abs() < 1e-14, "{got:?} vs {want:?}");
            }
        }
        assert_eq!(rotate(&[0.0; 4], v), [0.0; 3]);
    }
}
