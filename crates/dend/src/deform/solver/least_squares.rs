//! The paper's formulations' iteration (eq. (24) least squares and the
//! eq. (23) square system): STEP 2 and the local rotations on the pose,
//! one 3-column solve with the cached factor per iteration, a safeguard
//! that halves growing steps, and Anderson acceleration whose candidate is
//! kept when the objective falls.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::MatMut;
use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::scratch::Chain;
use super::{Deformer, StepReport};
use crate::deform::anderson::Anderson;
use crate::deform::constraints::Constraints;
use crate::deform::detail::local_rotations;
use crate::deform::energy::Shape;
use crate::deform::error::DeformError;
use crate::deform::factor::Factor;
use crate::deform::params::{DetailTerm, Mode};
use crate::deform::square::apply_p;
use crate::deform::stacked;
use crate::mesh::{Point, Real};

/// The safeguard's slack: a step may raise the objective by this factor
/// (the fixed point of the lagged iteration is not a minimiser of the
/// objective, so it may rise a little near convergence); beyond it the step
/// is halved, and three such steps in a row stop the iteration.
const SLACK: Real = 1.05;

/// Objective rises below `FLOOR ×` the objective at the start of a step (or
/// of a chain of steps) still halve the step but do not count towards
/// `diverged`: near convergence the objective fluctuates at that level.
const FLOOR: Real = 1e-6;

/// Longest run of Anderson candidates skipped after rejections: each
/// rejection doubles the run (1, 2, 4, 8), an accepted candidate ends it.
/// A rejected candidate costs a whole evaluation of the pose; measured on
/// the standard edit (100 iterations), eth_hand_14k evaluated 52
/// candidates and accepted 5, feline_50k 58 and 16; with the back-off 18
/// and 29, the same 5 and 16 accepted, 9 % and 2 % less time.
const MAX_AA_BACKOFF: u32 = 8;

/// Row count from which the residual `b - J Y` and `J_Uᵀ r` run on the
/// rayon pool, in chunks of [`ROW_CHUNK`] rows.
const PARALLEL_MIN_ROWS: usize = 4096;
const ROW_CHUNK: usize = 2048;

impl Deformer {
    /// [`Deformer::step`] for eq. (24) and eq. (23): up to `max_iters`
    /// DEND iterations, warm-started from the current pose (design.md §4.6, §9):
    /// each iteration is STEP 2 (and the local rotations) on the pose, then
    /// one 3-column solve with the cached factor. Each step is safeguarded:
    /// if the objective grows, the step is halved (up to 5 times); after
    /// three consecutive growing steps the iteration stops, keeps the best
    /// pose seen and reports `diverged`.
    ///
    /// `factor` must have been built for `constraints`' constrained set and
    /// this deformer's rest mesh and parameters.
    pub(super) fn step_least_squares(
        &mut self,
        factor: &Factor,
        constraints: &Constraints,
        max_iters: usize,
    ) -> Result<StepReport, DeformError> {
        self.prepare(factor);
        let moved = self.load_targets(factor, constraints)?;
        let s = &mut self.scratch;
        let chain = s
            .evaluated
            .take()
            .filter(|c| c.factor == factor.id() && !moved);
        let continued = chain.is_some();
        let mut f = match chain {
            Some(c) => c.f,
            None => self.evaluate(factor),
        };
        // whether scratch holds the evaluation of the current `y`
        let mut evaluated = true;
        // The Anderson history continues along a chain of steps on unchanged
        // targets (its pairs are iterates of the same fixed-point map) and
        // restarts whenever the targets or the pose were changed.
        if !continued {
            self.scratch.anderson.reset();
        }
        let accelerate = self.params.detail == DetailTerm::Nonlinear && self.params.anderson > 0;
        let mut report = StepReport {
            iterations: 0,
            last_update: 0.0,
            converged: false,
            diverged: false,
            objective: f,
            initial_objective: f,
            coarse_iterations: 0,
            coarse_ms: 0.0,
            coarse_work: 0.0,
            interrupted: false,
        };
        let (mut growing, mut best_f, f_start) = match chain {
            Some(c) => (c.growing, c.best_f, c.f_start),
            None => {
                self.scratch.best.clone_from(&self.y);
                (0, f, f)
            }
        };
        let (mut aa_skip, mut aa_backoff) = chain.map_or((0, 0), |c| (c.aa_skip, c.aa_backoff));
        // rises of the objective below this are not divergence
        let floor = FLOOR * f_start + 1e-20;
        let nu = factor.sys.unknowns.len();
        if nu == 0 {
            report.converged = true;
            self.sync_pose(factor);
            return Ok(report);
        }
        for _ in 0..max_iters {
            let Some(max_dx) = self.global_step(factor, nu) else {
                self.y.clone_from(&self.scratch.best);
                evaluated = false;
                report.diverged = true;
                break;
            };
            // acceleration: a candidate kept only if it lowers the objective
            let accepted = if accelerate {
                self.anderson_candidate(factor, f, (&mut aa_skip, &mut aa_backoff))
            } else {
                None
            };
            // safeguard: the plain step, halved while the objective grows
            let (f_new, step_len) = match accepted {
                Some(kept) => kept,
                None => self.halving_step(factor, f, max_dx),
            };
            report.iterations += 1;
            report.last_update = step_len;
            growing = if f_new > SLACK * f + floor {
                growing + 1
            } else {
                0
            };
            f = f_new;
            if f < best_f {
                best_f = f;
                self.scratch.best.clone_from(&self.y);
            }
            if !f.is_finite() || growing >= 3 {
                self.y.clone_from(&self.scratch.best);
                evaluated = false;
                f = best_f;
                report.diverged = true;
                break;
            }
            if report.last_update < self.params.tol {
                report.converged = true;
                break;
            }
        }
        if !report.converged && f > SLACK * best_f + floor {
            // an unconverged step ends within the safeguard's slack of the
            // best pose of its chain (not on the best pose itself: a chain of
            // one-iteration steps would then never leave it)
            self.y.clone_from(&self.scratch.best);
            evaluated = false;
            f = best_f;
        }
        report.objective = f;
        if evaluated {
            self.scratch.evaluated = Some(Chain {
                factor: factor.id(),
                f,
                growing,
                best_f,
                f_start,
                aa_skip,
                aa_backoff,
            });
        }
        self.sync_pose(factor);
        Ok(report)
    }

    /// The global step's solve: the update of the `nu` unknowns into
    /// `scratch.rhs` (the current iterate kept in `scratch.y_prev`) and its
    /// largest vertex move, or `None` when the solve is not finite.
    fn global_step(&mut self, factor: &Factor, nu: usize) -> Option<Real> {
        self.right_hand_side(factor);
        {
            let s = &mut self.scratch;
            let b = MatMut::from_column_major_slice_mut(&mut s.rhs, nu, 3);
            let mem = s.mem.as_mut().expect("scratch sized in prepare");
            factor.solve_in_place(b, MemStack::new(mem));
        }
        if self.scratch.rhs.iter().any(|v| !v.is_finite()) {
            return None;
        }
        self.scratch.y_prev.clone_from(&self.y);
        let max_dx = (0..nu)
            .map(|k| {
                let r = &self.scratch.rhs;
                (r[k] * r[k] + r[nu + k] * r[nu + k] + r[2 * nu + k] * r[2 * nu + k]).sqrt()
            })
            .fold(0.0, Real::max);
        Some(max_dx)
    }

    /// The Anderson candidate from the current iterate (`scratch.y_prev`)
    /// and its update (`scratch.rhs`): written to `y` and kept (returns its
    /// objective and largest move) only if its objective is at most `f`;
    /// after a rejection the next candidates are skipped for a while (1, 2,
    /// 4, .. [`MAX_AA_BACKOFF`] in a row) while the history keeps recording:
    /// on real meshes most candidates right after a rejection are rejected
    /// too.
    fn anderson_candidate(
        &mut self,
        factor: &Factor,
        f: Real,
        (aa_skip, aa_backoff): (&mut u32, &mut u32),
    ) -> Option<(Real, Real)> {
        let nu = factor.sys.unknowns.len();
        let s = &mut self.scratch;
        for (k, &u) in factor.sys.unknowns.iter().enumerate() {
            let p = s.y_prev[u as usize];
            s.x_flat[k] = p[0];
            s.x_flat[nu + k] = p[1];
            s.x_flat[2 * nu + k] = p[2];
        }
        let proposed = s.anderson.step(&s.x_flat, &s.rhs, &mut s.cand);
        let skip = *aa_skip > 0;
        *aa_skip = aa_skip.saturating_sub(1);
        if !proposed || skip {
            return None;
        }
        let mut mv: Real = 0.0;
        for (k, &u) in factor.sys.unknowns.iter().enumerate() {
            let c = [s.cand[k], s.cand[nu + k], s.cand[2 * nu + k]];
            let p = s.y_prev[u as usize];
            mv = mv.max(
                ((c[0] - p[0]).powi(2) + (c[1] - p[1]).powi(2) + (c[2] - p[2]).powi(2)).sqrt(),
            );
            self.y[u as usize] = c;
        }
        let f_aa = self.evaluate(factor);
        if f_aa.is_finite() && f_aa <= f {
            *aa_backoff = 0;
            Some((f_aa, mv))
        } else {
            self.scratch.anderson.reset();
            *aa_backoff = (2 * *aa_backoff).clamp(1, MAX_AA_BACKOFF);
            *aa_skip = *aa_backoff;
            None
        }
    }

    /// The plain step `y_prev + α Δ`, from `α = 1` halved while the
    /// objective exceeds `SLACK × f` (down to 1/16); returns its objective
    /// and largest move. A shortened step resets the Anderson history.
    fn halving_step(&mut self, factor: &Factor, f: Real, max_dx: Real) -> (Real, Real) {
        let nu = factor.sys.unknowns.len();
        let mut alpha = 1.0;
        let mut f_new;
        loop {
            for (k, &u) in factor.sys.unknowns.iter().enumerate() {
                let p = self.scratch.y_prev[u as usize];
                let r = &self.scratch.rhs;
                self.y[u as usize] = [
                    p[0] + alpha * r[k],
                    p[1] + alpha * r[nu + k],
                    p[2] + alpha * r[2 * nu + k],
                ];
            }
            f_new = self.evaluate(factor);
            if f_new <= SLACK * f + 1e-20 || alpha < 1.0 / 16.0 {
                break;
            }
            alpha *= 0.5;
        }
        if alpha < 1.0 {
            self.scratch.anderson.reset();
        }
        (f_new, alpha * max_dx)
    }

    /// Sizes the scratch memory for `factor` (once per constraint set).
    fn prepare(&mut self, factor: &Factor) {
        let n = self.y.len();
        let dims = (factor.sys.num_rows(), factor.sys.unknowns.len());
        let s = &mut self.scratch;
        if s.rot.len() != n {
            s.rot = vec![UnitQuaternion::identity(); n];
            s.tdelta = vec![[0.0; 3]; n];
            s.lv = vec![[0.0; 3]; n];
            s.dhat = vec![[0.0; 3]; n];
            s.e = vec![[0.0; 3]; n];
            s.gu = vec![[0.0; 3]; n];
            s.gv = vec![[0.0; 3]; n];
            s.glu = vec![[0.0; 3]; n];
            s.gx = vec![[0.0; 3]; n];
        }
        if s.sized_for != dims || s.mem.is_none() {
            s.r = vec![0.0; 3 * dims.0.max(dims.1)];
            s.rhs = vec![0.0; 3 * dims.1];
            s.mem = Some(MemBuffer::new(factor.solve_scratch(3)));
            s.anderson = Anderson::new(self.params.anderson, 3 * dims.1);
            s.x_flat = vec![0.0; 3 * dims.1];
            s.cand = vec![0.0; 3 * dims.1];
            s.sized_for = dims;
        }
    }

    /// STEP 2 and the local rotations on the current pose, then the residual
    /// `r = b - J Y` into scratch; returns the objective `|r|²` (+ the soft
    /// constraint term).
    fn evaluate(&mut self, factor: &Factor) -> Real {
        let rest = &*self.rest;
        let ops = &rest.ops;
        let topo = rest.mesh.topology();
        let s = &mut self.scratch;
        let nonlinear = self.params.detail == DetailTerm::Nonlinear;
        let rotated = nonlinear && self.params.mode() == Mode::Default;
        // δ̂ (paper eqs. 27–28), or δ for the linear term.
        if nonlinear {
            rest.mu(self.params.mode())
                .delta_hat(topo, &self.y, &mut s.dhat);
        } else {
            s.dhat.copy_from_slice(&ops.delta);
        }
        // Internal target: P (T δ) in the default mode (design.md §4.3), A X otherwise.
        if rotated {
            local_rotations(topo, rest.weights(), &ops.positions, &self.y, &mut s.rot);
            let base = if factor.energy.shape() == Shape::Right {
                &factor.ax
            } else {
                &ops.delta
            };
            for ((t, r), d) in s.tdelta.iter_mut().zip(&s.rot).zip(base) {
                let v = r * Vector3::from(*d);
                *t = [v.x, v.y, v.z];
            }
        }
        if let Some(sq) = &factor.square {
            let internal: &[Point] = if rotated {
                apply_p(factor.energy, -1.0, ops, &mut s.tdelta, &mut s.lv);
                &s.tdelta
            } else {
                &factor.ax
            };
            return sq.residual(
                &factor.sys,
                internal,
                &s.dhat,
                &self.y,
                &s.targets,
                &mut s.r,
            );
        }
        // r = b - J Y without J (stacked.rs): L Y on every row, then the
        // rows of R in parallel chunks (each writes its own rows of the
        // three columns of r)
        let sys = &factor.sys;
        let nr = sys.rows.len();
        let nrows = 2 * nr;
        let y = &self.y;
        let shape = factor.energy.shape();
        stacked::mul_l(ops, y, &mut s.lv);
        let ly = &s.lv;
        // A = P L: t - A Y = P(base - L Y); A = L (L - 2G): t - L (L Y - 2 G Y)
        let (target, e): (&[Point], &mut [Point]) = match shape {
            Shape::Left { .. } => {
                let base: &[Point] = if rotated { &s.tdelta } else { &ops.delta };
                for ((e, b), l) in s.e.iter_mut().zip(base).zip(ly) {
                    *e = [b[0] - l[0], b[1] - l[1], b[2] - l[2]];
                }
                (&[], &mut s.e)
            }
            Shape::Right => {
                for (i, e) in s.e.iter_mut().enumerate() {
                    let g2 = 2.0 * ops.g[i];
                    let (l, yi) = (ly[i], y[i]);
                    *e = [l[0] - g2 * yi[0], l[1] - g2 * yi[1], l[2] - g2 * yi[2]];
                }
                (if rotated { &s.tdelta } else { &factor.ax }, &mut s.e)
            }
        };
        let e: &[Point] = e;
        let dhat = &s.dhat;
        let row_residual = |row: usize| -> Point {
            if row < nr {
                let i = sys.rows[row] as usize;
                let v = match shape {
                    Shape::Left { .. } => stacked::p_row(shape, ops, i, e),
                    Shape::Right => {
                        let le = stacked::l_row(ops, i, e);
                        let t = target[i];
                        [t[0] - le[0], t[1] - le[1], t[2] - le[2]]
                    }
                };
                scale3(v, sys.row_weight[row])
            } else {
                let r = row - nr;
                let i = sys.rows[r] as usize;
                let (d, l) = (dhat[i], ly[i]);
                scale3(
                    [d[0] - l[0], d[1] - l[1], d[2] - l[2]],
                    sys.row_weight[r] * sys.sqrt_lambda2,
                )
            }
        };
        let obj = for_row_chunks(&mut s.r[..3 * nrows], |row, out| {
            let acc = row_residual(row);
            *out = acc;
            acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]
        });
        obj + sys.soft_energy(&s.targets, &self.y)
    }

    /// `rhs = J_Uᵀ r` (+ `λ1 (C - Y)` on constrained unknowns).
    fn right_hand_side(&mut self, factor: &Factor) {
        let sys = &factor.sys;
        let s = &mut self.scratch;
        let nu = sys.unknowns.len();
        let nrows = sys.num_rows();
        if factor.square.is_some() {
            s.rhs.copy_from_slice(&s.r[..3 * nu]); // the residual is already on the unknown rows
            return;
        }
        // J_Uᵀ r = (Aᵀ u + Lᵀ v)_U with u = W r_A, v = √λ2 W r_L (stacked.rs)
        let ops = &self.rest.ops;
        let nr = sys.rows.len();
        let shape = factor.energy.shape();
        let r = &s.r;
        s.gu.fill([0.0; 3]);
        s.gv.fill([0.0; 3]);
        for (k, &i) in sys.rows.iter().enumerate() {
            let (w, i) = (sys.row_weight[k], i as usize);
            let wl = w * sys.sqrt_lambda2;
            let d = nr + k;
            s.gu[i] = [w * r[k], w * r[nrows + k], w * r[2 * nrows + k]];
            s.gv[i] = [wl * r[d], wl * r[nrows + d], wl * r[2 * nrows + d]];
        }
        stacked::inner_gradient(shape, ops, &s.gu, &s.gv, &mut s.glu, &mut s.gx);
        let (x, lu) = (&s.gx, &s.glu);
        for_row_chunks(&mut s.rhs, |k, out| {
            let i = sys.unknowns[k] as usize;
            *out = stacked::lt_row(ops, i, x);
            if shape == Shape::Right {
                let g2 = 2.0 * ops.g[i];
                for d in 0..3 {
                    out[d] -= g2 * lu[i][d];
                }
            }
            0.0
        });
        sys.add_soft_rhs(&s.targets, &self.y, &mut s.rhs);
    }
}

/// Writes every row of the column-major `len × 3` buffer `buf` by
/// `f(row, &mut value)` and returns the sum of what `f` returns; in chunks of
/// [`ROW_CHUNK`] rows on the rayon pool from [`PARALLEL_MIN_ROWS`] rows.
fn for_row_chunks(buf: &mut [Real], f: impl Fn(usize, &mut Point) -> Real + Sync) -> Real {
    let len = buf.len() / 3;
    let (c0, rest) = buf.split_at_mut(len);
    let (c1, c2) = rest.split_at_mut(len);
    let chunk = |start: usize, (c0, (c1, c2)): (&mut [Real], (&mut [Real], &mut [Real]))| {
        let mut sum = 0.0;
        let rows = c0.iter_mut().zip(c1.iter_mut()).zip(c2.iter_mut());
        for (k, ((a, b), c)) in rows.enumerate() {
            let mut out = [0.0; 3];
            sum += f(start + k, &mut out);
            (*a, *b, *c) = (out[0], out[1], out[2]);
        }
        sum
    };
    if len >= PARALLEL_MIN_ROWS {
        c0.par_chunks_mut(ROW_CHUNK)
            .zip(
                c1.par_chunks_mut(ROW_CHUNK)
                    .zip(c2.par_chunks_mut(ROW_CHUNK)),
            )
            .enumerate()
            .map(|(i, cols)| chunk(i * ROW_CHUNK, cols))
            .sum()
    } else {
        chunk(0, (c0, (c1, c2)))
    }
}

#[inline]
fn scale3(p: Point, s: Real) -> Point {
    [p[0] * s, p[1] * s, p[2] * s]
}

#[cfg(test)]
#[path = "least_squares_tests.rs"]
mod tests;
