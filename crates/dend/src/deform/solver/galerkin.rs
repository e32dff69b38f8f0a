//! A Galerkin coarse correction of the fine pose: one Newton step of the
//! reduced energy restricted to the blended rigid motions of aggregates of
//! vertices (`elastic/hessian/galerkin.rs` builds its matrix).
//!
//! The aggregates are the fine vertices nearest each vertex of a coarse
//! level (`CoarseLevel::near`, composed down `depth` levels), and each
//! unknown's weights in them are that partition smoothed
//! [`Galerkin::smooth`] times over the mesh's edges
//! ([`smoothed_weights`]): one pass took camel_9770's settle from 13 to 9
//! iterations, feline_50k's from 19 to 10 and armadillo_43k's from 57 to
//! 38, for an assembly about twice as dear. The step
//! solves `(Pᵀ H P) δ = Pᵀ r`, with `r = −½ ∇E` the residual the global
//! step forms and `H` the Newton matrix of `solver/newton.rs` in its
//! Gauss–Newton model ([`Curvature::GaussNewton`]: on camel_9770's arc
//! gesture the same iterations as its convex projection, at less than
//! half the assembly's time, which no eigensystem then dominates); `P`
//! blends the aggregates' turns about their centroids at the pose of the
//! assembly.
//! `D = P δ` is kept at the first `α` whose energy (rotations refitted)
//! is below the current one. `G = Pᵀ H P` and its factor serve
//! [`Galerkin::lag`] corrections: near a minimum `H` changes slowly, and
//! the assembly costs several fine iterations. Unlike the coarse problem
//! of `multilevel.rs`, a re-discretised energy on a coarse mesh whose
//! correction removes a fixed share of the error (docs/performance.md),
//! `Pᵀ H P` is the fine energy's own curvature in the coarse space.

use std::time::Instant;

use dend_linalg::cholesky::{self, Refactor};
use dend_linalg::ordering::FillOrdering;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::LltRef;
use faer::{Conj, MatMut, Par};
use nalgebra::Vector3;

use super::galerkin_state::GalerkinState;
use super::levels::CoarseRun;
use super::multilevel::Correction;
use super::{Deformer, Galerkin};
use crate::deform::elastic::hessian::galerkin::{slot, RigidSpace, Weights};
use crate::deform::elastic::hessian::Curvature;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::mesh::Real;

impl Deformer {
    /// Builds the Galerkin corrections' per-set state for `factor`
    /// (aggregates, the coarse matrix's pattern and symbolic analysis)
    /// unless it is built: a constraint set's precomputation
    /// ([`Deformer::prepare_levels`]).
    pub(super) fn prepare_galerkin(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        mode: Galerkin,
    ) {
        self.galerkin_state(factor, (el, set), mode);
    }

    fn galerkin_state(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        Galerkin { depth, smooth, .. }: Galerkin,
    ) -> Option<()> {
        if self.galerkin.as_ref().map(|g| g.factor_id) == Some(factor.id()) {
            return Some(());
        }
        self.galerkin = None;
        let t0 = Instant::now();
        let ratio = self.params.elastic()?.coarse_ratio;
        let n = self.y.len();
        let mut of: Vec<u32> = (0..n as u32).collect();
        let mut level = self.rest.coarse_at_most(ratio)?;
        for d in 0..depth {
            for v in of.iter_mut() {
                *v = level.near[*v as usize];
                if *v == u32::MAX {
                    return None;
                }
            }
            if d + 1 < depth {
                // a mesh with fewer levels aggregates over all it has
                match level.rest.coarse_at_most(ratio) {
                    Some(l) => level = l,
                    None => break,
                }
            }
        }
        let sys = &factor.sys;
        let mut compact = vec![u32::MAX; n];
        let mut n_agg = 0;
        let agg: Vec<u32> = sys
            .unknowns
            .iter()
            .map(|&u| {
                let c = &mut compact[of[u as usize] as usize];
                if *c == u32::MAX {
                    *c = n_agg;
                    n_agg += 1;
                }
                *c
            })
            .collect();
        let weights = smoothed_weights(agg, smooth, &self.rest.ops.l, &sys.unknowns, &sys.col_of);
        let elements = el.coupling_elements(set, &self.rest.ops, &sys.col_of);
        let q = el.without_area(&elements, &sys.m);
        let space = RigidSpace::new(weights, n_agg as usize, &elements, &q);
        let g = space.pattern();
        let symbolic =
            cholesky::analyse(&g.proper_indptr(), g.indices(), FillOrdering::default()).ok()?;
        let refactor = Refactor::new(&symbolic, &g).ok()?;
        let mem = MemBuffer::try_new(symbolic.solve_in_place_scratch::<Real>(1, Par::Seq)).ok()?;
        self.galerkin = Some(Box::new(GalerkinState {
            factor_id: factor.id(),
            lever: vec![Vector3::zeros(); space.weights.agg.len()],
            centre: vec![Vector3::zeros(); space.len()],
            rhs: vec![0.0; 6 * space.len()],
            space,
            elements,
            q,
            g,
            symbolic,
            refactor,
            mem,
            age: None,
        }));
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(ms, aggregates = n_agg, "galerkin state built");
        Some(())
    }

    /// One Galerkin correction of the pose with energy `e` (module docs).
    pub(super) fn galerkin_correction(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        e: Real,
        mode: Galerkin,
    ) -> Correction {
        let t0 = Instant::now();
        // (the work of a correction that reuses `G`: its residual and
        // energy test cost about one fine iteration; an assembly of `G`
        // costs several more, which this count leaves out: compare
        // Galerkin runs by time, docs/performance.md)
        let run = |t0: Instant| CoarseRun {
            iterations: 1,
            ms: t0.elapsed().as_secs_f64() * 1e3,
            work: 1.0,
        };
        if self.galerkin_state(factor, (el, set), mode).is_none() {
            return Correction::Unavailable(run(t0));
        }
        self.global_rhs(factor, (el, set));
        let t_rhs = t0.elapsed().as_secs_f64() * 1e3;
        let lag = mode.lag;
        let stale = self
            .galerkin
            .as_ref()
            .is_some_and(|g| g.age.is_some_and(|a| a < lag));
        if !stale && !self.assemble_galerkin(factor, el) {
            return Correction::Dropped(run(t0));
        }
        let t_asm = t0.elapsed().as_secs_f64() * 1e3;
        let out = self.galerkin_step(factor, (el, set), e);
        let out = match out {
            None if stale => {
                // a lagged `G` failed: assemble it at this pose and retry
                if !self.assemble_galerkin(factor, el) {
                    return Correction::Dropped(run(t0));
                }
                self.global_rhs(factor, (el, set));
                self.galerkin_step(factor, (el, set), e)
            }
            out => out,
        };
        let t_all = t0.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(stale, t_rhs, t_asm, t_all, ?out, e, "galerkin correction");
        if let Some(g) = self.galerkin.as_mut() {
            g.age = g.age.map(|a| a + 1);
        }
        match out {
            Some(e_new) => Correction::Kept(e_new, run(t0)),
            None => Correction::Dropped(run(t0)),
        }
    }

    /// Assembles and factors `G` at the current pose (lever arms about the
    /// aggregates' centroids now); whether it factored.
    fn assemble_galerkin(&mut self, factor: &Factor, el: &ElasticOps) -> bool {
        let gs = self.galerkin.as_mut().expect("built before");
        let unknowns = &factor.sys.unknowns;
        // each aggregate's weighted centroid, each entry's lever arm
        let space = &gs.space;
        let wts = &space.weights;
        let at =
            |e: usize| Vector3::from(self.y[unknowns[space.entry_unknown[e] as usize] as usize]);
        for a in 0..space.len() {
            let (mut c, mut sum) = (Vector3::zeros(), 0.0);
            for &e in space.members(a) {
                let e = e as usize;
                c += wts.w[e] * at(e);
                sum += wts.w[e];
            }
            gs.centre[a] = c / sum;
        }
        for (e, r) in gs.lever.iter_mut().enumerate() {
            *r = at(e) - gs.centre[wts.agg[e] as usize];
        }
        let st = &self.elastic;
        let t0 = Instant::now();
        el.galerkin_matrix(
            space,
            &gs.elements,
            &self.rest.ops,
            &gs.q,
            (&self.y, &st.rot, &st.proj),
            &gs.lever,
            Curvature::GaussNewton,
            &mut gs.g,
        );
        let t_matrix = t0.elapsed().as_secs_f64() * 1e3;
        regularise(&mut gs.g, space.len());
        gs.age = Some(0);
        let ok = gs.refactor.factorise_definite(&gs.symbolic, &gs.g).is_ok();
        let t_factor = t0.elapsed().as_secs_f64() * 1e3 - t_matrix;
        tracing::debug!(
            t_matrix,
            t_factor,
            ok,
            nnz = gs.g.nnz(),
            "galerkin assembly"
        );
        ok
    }

    /// The step `D = P G⁻¹ Pᵀ r` (`r` in `rhs`, from [`Deformer::global_rhs`])
    /// and its line search; the energy kept, `None` with the pose unchanged.
    fn galerkin_step(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        e: Real,
    ) -> Option<Real> {
        let nu = factor.sys.unknowns.len();
        let unknowns = &factor.sys.unknowns;
        let gs = self.galerkin.as_mut().expect("built before");
        let space = &gs.space;
        let st = &mut self.elastic;
        // Pᵀ r
        let wts = &space.weights;
        gs.rhs.fill(0.0);
        for k in 0..nu {
            let r = Vector3::new(st.rhs[k], st.rhs[nu + k], st.rhs[2 * nu + k]);
            for f in wts.entries(k) {
                let a = wts.agg[f] as usize;
                let t = wts.w[f] * r;
                let m = gs.lever[f].cross(&t);
                for i in 0..3 {
                    gs.rhs[6 * a + i] += t[i];
                    gs.rhs[6 * a + 3 + i] += m[i];
                }
            }
        }
        let n = 6 * space.len();
        let llt = LltRef::new(&gs.symbolic, gs.refactor.values());
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut gs.rhs, n, 1),
            Par::Seq,
            MemStack::new(&mut gs.mem),
        );
        if gs.rhs.iter().any(|v| !v.is_finite()) {
            return None;
        }
        for (k, &u) in unknowns.iter().enumerate() {
            let y = self.y[u as usize];
            let mut d = Vector3::zeros();
            for f in wts.entries(k) {
                let a = wts.agg[f] as usize;
                let t = Vector3::new(gs.rhs[6 * a], gs.rhs[6 * a + 1], gs.rhs[6 * a + 2]);
                let w = Vector3::new(gs.rhs[6 * a + 3], gs.rhs[6 * a + 4], gs.rhs[6 * a + 5]);
                d += wts.w[f] * (t + w.cross(&gs.lever[f]));
            }
            for i in 0..3 {
                st.x_flat[i * nu + k] = y[i];
                // (the step, kept in `rhs` beside the current unknowns)
                st.rhs[i * nu + k] = d[i];
            }
        }
        self.line_search_rhs(factor, (el, set), e)
    }
}

/// Makes `G` definite where an aggregate's turns have no stiffness (one
/// unknown, or all on a line): a relative shift of each turn's diagonal
/// by its aggregate's translation stiffness (lengths in mean edges).
fn regularise(g: &mut sprs::CsMat<Real>, n_agg: usize) {
    let indptr = g.indptr().raw_storage().to_vec();
    let indices = g.indices().to_vec();
    let data = g.data_mut();
    let diag = |r: usize| -> usize {
        let (s, e) = (indptr[r], indptr[r + 1]);
        s + indices[s..e].binary_search(&r).expect("a diagonal entry")
    };
    for a in 0..n_agg {
        let t = (0..3).map(|i| data[diag(6 * a + i)]).fold(0.0, Real::max);
        for i in 0..6 {
            let d = diag(6 * a + i);
            data[d] += 1e-8 * t;
        }
    }
}

/// Below this share an unknown's weight in an aggregate is dropped after
/// smoothing (the rest renormalised): a long thin tail of small weights
/// would widen `G`'s pattern for little gain.
const MIN_WEIGHT: Real = 0.05;

/// The weights of the partition `agg` (one aggregate per unknown)
/// smoothed `passes` times across the mesh's edges between unknowns: each
/// pass averages an unknown's weights half with the mean of its
/// neighbours' (edges from the pattern of the Laplacian `l`; `unknowns`
/// and `col_of` map unknowns to vertices and back). The weights stay a
/// partition of unity and depend on the connectivity only, not on the
/// unit of length.
pub(super) fn smoothed_weights(
    agg: Vec<u32>,
    passes: usize,
    l: &sprs::CsMat<Real>,
    unknowns: &[u32],
    col_of: &[u32],
) -> Weights {
    if passes == 0 {
        return Weights::partition(agg);
    }
    let nu = agg.len();
    // each unknown's neighbouring unknowns, once for all passes
    let neighbours: Vec<Vec<u32>> = (0..nu)
        .map(|k| {
            let v = unknowns[k] as usize;
            l.outer_view(v)
                .map(|row| {
                    row.indices()
                        .iter()
                        .map(|&j| col_of[j])
                        .filter(|&c| c != u32::MAX && c as usize != k)
                        .collect()
                })
                .unwrap_or_default()
        })
        .collect();
    let mut cur: Vec<Vec<(u32, Real)>> = agg.iter().map(|&a| vec![(a, 1.0)]).collect();
    for _ in 0..passes {
        let next: Vec<Vec<(u32, Real)>> = (0..nu)
            .map(|k| {
                let ns = &neighbours[k];
                if ns.is_empty() {
                    return cur[k].clone();
                }
                let mut out: Vec<(u32, Real)> = cur[k].iter().map(|&(a, w)| (a, 0.5 * w)).collect();
                let share = 0.5 / ns.len() as Real;
                for &j in ns {
                    for &(a, w) in &cur[j as usize] {
                        let i = slot(&mut out, a, 0.0);
                        out[i].1 += share * w;
                    }
                }
                out
            })
            .collect();
        cur = next;
    }
    let mut ptr = Vec::with_capacity(nu + 1);
    let (mut aggs, mut ws) = (Vec::new(), Vec::new());
    ptr.push(0);
    for mut entries in cur {
        let top = entries.iter().map(|x| x.1).fold(0.0, Real::max);
        entries.retain(|x| x.1 >= MIN_WEIGHT.min(top));
        entries.sort_unstable_by_key(|x| x.0);
        let sum: Real = entries.iter().map(|x| x.1).sum();
        for (a, w) in entries {
            aggs.push(a);
            ws.push(w / sum);
        }
        ptr.push(aggs.len());
    }
    Weights {
        ptr,
        agg: aggs,
        w: ws,
    }
}
