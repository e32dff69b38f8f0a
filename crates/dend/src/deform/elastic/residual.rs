//! The elastic energy's residual `g(R, P) − Q Y` (the global step's right
//! side; parent module docs), from the factors of `Q` rather than `Q`.
//!
//! `Q = K_c + Lbar diag(k_L λ2 k_b [i ∈ F̃]) L − k_a Lbar` (parent module
//! docs): its assembled rows hold the 2-ring of each vertex (19 entries on
//! a regular mesh), while `K_c`, `Lbar` and `L` hold the 1-ring. So a
//! first pass forms `t = k_a Y − kbl [F̃] ∘ (L Y)` per vertex, and each
//! row then sums over its spokes only:
//!
//! ```text
//!   out_v = Lbar_vv t_v + Σ_j (c_vj [v ∈ F̃] + c_jv [j ∈ F̃]) (y_j − y_v) + Lbar_vj t_j
//!           − [v ∈ F̃] R_v o_v − Σ_j [j ∈ F̃] R_j f_vj + Σ_t a_t (P_t Bᵀ) at v
//!   o_v  = Σ_j c_vj e_vj − kbl Lbar_vv [b_v > 0] δ_v
//!   f_vj = c_jv e_vj − kbl Lbar_vj [b_j > 0] δ_j
//! ```
//!
//! (the Laplacian term's `kbl Lbar t̂`, `t̂_j = [j ∈ F̃] R_j δ_j`, rotates
//! with the spokes' `R_j`, so every spoke costs one rotation). A rotation
//! is applied as `R x = x + (R − I) x`: the `x` part summed once per
//! constraint set ([`super::ResidualRows::rest_turn`]), and `(R − I) x` from the
//! quaternion scaled by `√2` in two cross products ([`turn`]). Against the
//! assembled rows the residual took 18–32 % less time (feline 50k, camel
//! 9770, hand 1502; one thread).

use nalgebra::UnitQuaternion;
use rayon::prelude::*;

use super::{ElasticOps, ElasticSet, PARALLEL_MIN};
use crate::mesh::{Point, Real};
use crate::operators::Operators;

/// Rows per block of the residual's passes (one call into AVX2 code each).
const ROW_BLOCK: usize = 256;

impl ElasticOps {
    /// `out = g(R, P) − Q Y` (module docs), `#V`: the negative half-gradient
    /// of `E` in `Y` at fixed `R` and `P`. `t` (`#V`) and `rm` (`#V`, the
    /// rotations scaled for [`turn`]) are scratch. `ops` are the operators
    /// `self` was built on (its rows hold what it needs of them).
    ///
    /// Every vertex's row is summed on its own (its spokes, and the area
    /// forces of its triangles, gathered: [`super::AreaForces`]), so the
    /// rows run in parallel and in the same order for any thread count.
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
        debug_assert_eq!(ops.num_vertices(), n);
        let rows = &self.rows;
        let free = &set.free;
        // √2 q_i where i is free (else 0, which turns nothing), and
        // t_i = k_a y_i − kbl [i free] (L Y)_i
        let first = |(i, (r, ti)): (usize, (&mut [Real; 4], &mut Point))| {
            *r = if free[i] {
                let q = rot[i].quaternion();
                let s = std::f64::consts::SQRT_2;
                [s * q.w, s * q.i, s * q.j, s * q.k]
            } else {
                [0.0; 4]
            };
            let mut acc = y[i].map(|c| rows.ka * c);
            if rows.kbl > 0.0 && free[i] {
                let mut ly = y[i].map(|c| rows.l_diag[i] * c);
                for s in rows.ptr[i]..rows.ptr[i + 1] {
                    let (j, w) = (rows.nbr[s] as usize, rows.l[s]);
                    for a in 0..3 {
                        ly[a] += w * y[j][a];
                    }
                }
                for a in 0..3 {
                    acc[a] -= rows.kbl * ly[a];
                }
            }
            *ti = acc;
        };
        // (blocks of rows, each compiled with AVX2 where the CPU has it:
        // wider vectors, the same arithmetic, `dend_linalg::cpu`)
        let first_block = |(b, (rm, t)): (usize, (&mut [[Real; 4]], &mut [Point]))| {
            dend_linalg::cpu::with_avx2_fma(|| {
                let i0 = b * ROW_BLOCK;
                rm.iter_mut()
                    .zip(t.iter_mut())
                    .enumerate()
                    .for_each(|(k, pair)| first((i0 + k, pair)));
            })
        };
        if n >= PARALLEL_MIN {
            rm.par_chunks_mut(ROW_BLOCK)
                .zip(t.par_chunks_mut(ROW_BLOCK))
                .enumerate()
                .for_each(first_block);
        } else {
            rm.chunks_mut(ROW_BLOCK)
                .zip(t.chunks_mut(ROW_BLOCK))
                .enumerate()
                .for_each(first_block);
        }
        let (t, rm): (&[Point], &[[Real; 4]]) = (t, rm);
        let row = |(v, o): (usize, &mut Point)| {
            let (yv, fv) = (y[v], free[v]);
            let (rest, own) = (set.rest_turn[v], turn(&rm[v], rows.own[v]));
            let mut acc = [0.0; 3];
            for a in 0..3 {
                acc[a] = rows.lbar_diag[v] * t[v][a] - rest[a] - own[a];
            }
            for s in rows.ptr[v]..rows.ptr[v + 1] {
                let j = rows.nbr[s] as usize;
                let sp = &rows.spoke[s];
                let k = if fv { sp.c_out } else { 0.0 } + if free[j] { sp.c_in } else { 0.0 };
                let turned = turn(&rm[j], sp.f);
                for a in 0..3 {
                    acc[a] += k * (y[j][a] - yv[a]) + sp.lbar * t[j][a] - turned[a];
                }
            }
            self.area_forces.add(v, proj, &mut acc);
            *o = acc;
        };
        let row_block = |(b, out): (usize, &mut [Point])| {
            dend_linalg::cpu::with_avx2_fma(|| {
                let v0 = b * ROW_BLOCK;
                out.iter_mut()
                    .enumerate()
                    .for_each(|(k, o)| row((v0 + k, o)));
            })
        };
        if n >= PARALLEL_MIN {
            out.par_chunks_mut(ROW_BLOCK)
                .enumerate()
                .for_each(row_block);
        } else {
            out.chunks_mut(ROW_BLOCK).enumerate().for_each(row_block);
        }
    }
}

/// `(R − I) x` for the rotation of the unit quaternion `(w, u)` given as
/// `q = √2 (w, u)`: `R x = x + 2w (u × x) + 2 u × (u × x)`, so with
/// `τ = √2 u × x` it is `√2 w τ + √2 u × τ`. 0 for `q = 0`.
#[inline(always)]
fn turn(q: &[Real; 4], x: Point) -> Point {
    let [w, a, b, c] = *q;
    let t = [
        b * x[2] - c * x[1],
        c * x[0] - a * x[2],
        a * x[1] - b * x[0],
    ];
    [
        w * t[0] + (b * t[2] - c * t[1]),
        w * t[1] + (c * t[0] - a * t[2]),
        w * t[2] + (a * t[1] - b * t[0]),
    ]
}

#[cfg(test)]
mod tests {
    use super::turn;
    use nalgebra::{UnitQuaternion, Vector3};

    /// `x + turn(√2 q, x)` is nalgebra's rotation of `x` by the unit
    /// quaternion `q`, and `turn` of the zero quaternion is 0 (a vertex
    /// whose rows are dropped).
    #[test]
    fn turning_is_the_quaternions_rotation_minus_the_identity() {
        let mut state = 99u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..200 {
            let q = UnitQuaternion::from_scaled_axis(Vector3::new(rnd(), rnd(), rnd()) * 3.0);
            let x = [rnd() * 5.0, rnd() * 5.0, rnd()];
            let c = q.quaternion();
            let s = std::f64::consts::SQRT_2;
            let d = turn(&[s * c.w, s * c.i, s * c.j, s * c.k], x);
            let want = q * Vector3::from(x);
            for a in 0..3 {
                assert!(
                    (x[a] + d[a] - want[a]).abs() < 1e-14 * 8.0,
                    "{q:?} {x:?}: {d:?}"
                );
            }
        }
        assert_eq!(turn(&[0.0; 4], [0.3, -1.7, 2.2]), [0.0; 3]);
    }
}
