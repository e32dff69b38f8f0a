//! How well each coarse level stands for the fine mesh: the level's own
//! minimum of an edit against the fine minimum.
//!
//! A coarse correction and the coarse start can only be as good as the
//! level's model (docs/performance.md): a level whose own minimum of an
//! edit lies far from the fine minimum sends the fine iteration towards
//! another pose, which the fine iterations and the later corrections then
//! have to undo. This measures that distance directly, independently of
//! the solver's schedule: the fine minimum (the hierarchy's solve to the
//! given tolerance), then each level's problem alone ([`Levels::One`],
//! its restricted constraints, the same weights) solved from its rest
//! pose, and the distance between the two at the level's vertices (which
//! are fine vertices). Under refinement of the fine mesh a consistent
//! discretisation brings each level's minimum closer to the fine one.

use std::sync::Arc;

use super::multilevel::coarse_params;
use super::{Deformer, Levels};
use crate::deform::constraints::Constraints;
use crate::deform::error::DeformError;
use crate::deform::factor::Factor;
use crate::deform::params::Params;
use crate::deform::rest::Rest;
use crate::mesh::{Point, Real};

/// The fine minimum of an edit and each coarse level's own minimum
/// ([`level_minima`]).
#[derive(Debug, Clone, serde::Serialize)]
pub struct LevelMinima {
    /// The fine solve's iterations.
    pub fine_iterations: usize,
    /// Whether the fine solve converged.
    pub fine_converged: bool,
    /// The fine objective at its minimum, in the mesh's units (length²).
    pub fine_objective: Real,
    /// The detail weight `k_L` of each level against the level above it
    /// ([`level_minima_with_detail`]; 1: the fine weights on every level).
    pub detail_scale: Real,
    /// The levels below the fine mesh, finest first.
    pub levels: Vec<LevelMinimum>,
}

/// One coarse level's own minimum of an edit against the fine minimum.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LevelMinimum {
    /// The level's vertex count.
    pub vertices: usize,
    /// The level's own solve's iterations.
    pub iterations: usize,
    /// Whether the level's own solve converged.
    pub converged: bool,
    /// The largest distance between the level's minimum and the fine
    /// minimum at the level's vertices, over the fine mesh's bounding-box
    /// diagonal.
    pub max_over_diagonal: Real,
    /// The root-mean-square of the same distances, over the diagonal.
    pub rms_over_diagonal: Real,
    /// The level's objective at its own minimum, in the mesh's units
    /// (length²).
    pub objective_own: Real,
    /// The level's objective at the fine minimum's positions of its
    /// vertices (mesh units): above `objective_own` by how much lower the
    /// level's model puts its own pose than the fine one.
    pub objective_at_fine: Real,
}

/// Solves `constraints` (the mesh's own indices) on `rest` with every level
/// to `params.tol`, then each level of the hierarchy alone from its rest
/// pose (its tolerance in its own mean edge lengths, as a correction's),
/// every solve at most `params.max_iters` iterations, and measures each level's minimum
/// against the fine one (module docs). A formulation without levels, or a
/// mesh too small for one, gives no levels.
pub fn level_minima(
    rest: &Arc<Rest>,
    params: &Params,
    constraints: &Constraints,
) -> Result<LevelMinima, DeformError> {
    level_minima_with_detail(rest, params, constraints, 1.0)
}

/// [`level_minima`] with each level's detail weight `k_L` times `detail`
/// against the level above it (the fine mesh's unchanged), as the solver's
/// levels take it once their corrections find them too stiff
/// (`solver/detail_fit.rs`): how close that model puts each level's own
/// minimum to the fine one.
pub fn level_minima_with_detail(
    rest: &Arc<Rest>,
    params: &Params,
    constraints: &Constraints,
    detail: Real,
) -> Result<LevelMinima, DeformError> {
    let factor = Factor::build(rest, params, constraints)?;
    let mut fine = Deformer::new(rest.clone(), *params);
    fine.set_levels(Levels::Many);
    let report = fine.step(&factor, constraints, params.max_iters)?;
    let scale2 = |r: &Rest| r.ops.scale * r.ops.scale;
    let mut out = LevelMinima {
        fine_iterations: report.iterations,
        fine_converged: report.converged,
        fine_objective: report.objective * scale2(rest),
        detail_scale: detail,
        levels: Vec::new(),
    };
    let Some(ratio) = params.elastic().map(|e| e.coarse_ratio) else {
        return Ok(out);
    };
    let diagonal = rest.mesh().diagonal();
    // the fine minimum in the solver's order, in the mesh's units; each
    // level's vertices are vertices of the level above in its solver order
    let mut at_fine: Vec<Point> = fine.y.iter().map(|&p| rest.ops.denormalise(p)).collect();
    let mut cc = rest.internal_constraints(constraints).into_owned();
    let (mut above, mut params_above) = (rest.clone(), *params);
    while let Some(level) = above.coarse_at_most(ratio) {
        let Some(restricted) = level.restrict(&cc) else {
            break;
        };
        cc = restricted;
        at_fine = level.fine_of.iter().map(|&v| at_fine[v as usize]).collect();
        // (each level's tolerance in its own mean edge lengths, from the
        // level above's, as a correction's)
        let p =
            coarse_params(&above, &params_above, &level).with_elastic(|e| e.laplacian *= detail);
        let r = &level.rest;
        let f = Factor::build(r, &p, &cc)?;
        let mut own = Deformer::new(r.clone(), p);
        own.set_levels(Levels::One);
        let solved = own.step(&f, &cc, p.max_iters)?;
        let (max, sum2) = own
            .pose()
            .iter()
            .zip(&at_fine)
            .map(|(a, b)| {
                let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
                d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            })
            .fold((0.0, 0.0), |(m, s): (Real, Real), d2| (m.max(d2), s + d2));
        // the same deformer at the fine minimum's positions, no iteration
        // (a coarse level keeps its own vertex order: its poses are in it)
        own.set_pose(at_fine.clone())?;
        let objective_at_fine = own.step(&f, &cc, 0)?.objective * scale2(r);
        out.levels.push(LevelMinimum {
            vertices: level.num_vertices(),
            iterations: solved.iterations,
            converged: solved.converged,
            max_over_diagonal: max.sqrt() / diagonal,
            rms_over_diagonal: (sum2 / at_fine.len().max(1) as Real).sqrt() / diagonal,
            objective_own: solved.objective * scale2(r),
            objective_at_fine,
        });
        above = level.rest.clone();
        params_above = p;
    }
    Ok(out)
}
