//! The solver tests' set-ups: the least-squares parameters, a solve from
//! rest, the tube and standard edits, and the distance between poses.

use std::sync::Arc;
use std::time::{Duration, Instant};

use dend::deform::{
    BoxSel, Constraints, ConstraintsSpec, DeformError, Deformer, Factor, Formulation, HandleSpec,
    Levels, Params, Rest, RigidTransform, RotationSpec, StepReport, VertexSet,
};
use dend::mesh::{Mesh, Point};
use nalgebra::{UnitQuaternion, Vector3};

/// Largest distance between corresponding points.
pub fn max_dist(a: &[Point], b: &[Point]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

/// Eq. (24) least squares (the default before the elastic formulation),
/// the parameters of the tests of that formulation's properties; the
/// elastic default's are in tests/it/elastic.rs.
pub fn ls() -> Params {
    Params::default().with_formulation(Formulation::LeastSquares)
}

/// Solves `spec` on `mesh` from rest with up to `iters` iterations.
pub fn solve(
    mesh: &Mesh,
    params: Params,
    spec: &ConstraintsSpec,
    iters: usize,
) -> (Vec<[f64; 3]>, StepReport) {
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = spec.resolve(mesh).unwrap();
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    let rep = d.step(&f, &c, iters).unwrap();
    (d.pose().to_vec(), rep)
}

/// A tube's edit along z: the vertices within 0.3 of its bottom (z = 0)
/// fixed, those within 0.3 of its top the handle `handle` (whose own
/// vertex set is replaced).
pub fn tube_spec(mesh: &Mesh, handle: HandleSpec) -> ConstraintsSpec {
    let (_, hi) = mesh.bounding_box();
    ConstraintsSpec {
        fixed_positions: None,
        fixed: VertexSet::Box {
            bbox: BoxSel {
                min: [-9.0, -9.0, -0.01],
                max: [9.0, 9.0, 0.01 * hi[2] + 0.3],
            },
        },
        handles: vec![HandleSpec {
            vertices: VertexSet::Box {
                bbox: BoxSel {
                    min: [-9.0, -9.0, hi[2] * 0.99 - 0.3],
                    max: [9.0, 9.0, hi[2] + 1.0],
                },
            },
            ..handle
        }],
    }
}

/// A handle named `top` with this motion and no vertices yet (see
/// [`tube_spec`]).
pub fn handle(translate: Option<[f64; 3]>, rotate: Option<RotationSpec>) -> HandleSpec {
    HandleSpec {
        name: Some("top".into()),
        vertices: VertexSet::Indices(vec![]),
        translate,
        rotate,
        pivot: None,
        positions: None,
    }
}

/// The standard edit: fixed = the lowest 10 % of vertices in z, handle = the
/// highest 10 %, moved by `0.15 · diagonal` along x and rotated 30° about y
/// (about the handle's centroid).
pub fn standard_edit(mesh: &Mesh) -> Constraints {
    let (fixed, handle) = bottom_top(mesh, 0.1);
    let c = centroid(mesh, &handle);
    let d = mesh.diagonal();
    let target = RigidTransform {
        rotation: UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians()),
        translation: [0.15 * d, 0.0, 0.0],
        pivot: c,
    };
    Constraints::new(mesh, fixed, vec![("top".into(), handle, Some(target))])
        .expect("standard edit is valid")
}

/// Vertex indices of the lowest and highest `frac` of vertices in z.
pub fn bottom_top(mesh: &Mesh, frac: f64) -> (Vec<u32>, Vec<u32>) {
    let n = mesh.num_vertices();
    let mut order: Vec<u32> = (0..n as u32).collect();
    let z = |v: &u32| mesh.positions()[*v as usize][2];
    order.sort_by(|a, b| z(a).total_cmp(&z(b)));
    let k = ((n as f64 * frac) as usize).max(1);
    let fixed = order[..k].to_vec();
    let handle = order[n - k..].to_vec();
    (fixed, handle)
}

fn centroid(mesh: &Mesh, vs: &[u32]) -> Point {
    let mut c = [0.0; 3];
    for &v in vs {
        let p = mesh.positions()[v as usize];
        for k in 0..3 {
            c[k] += p[k] / vs.len() as f64;
        }
    }
    c
}

/// Times one fine iteration as a solve runs it: the unit of the
/// fine-iteration equivalents that benches and examples report
/// (docs/performance.md). Each timed iteration is one of the 2nd to the
/// 12th of a sequence from rest on the fine mesh alone
/// ([`Levels::One`]): Anderson's candidate and its energy test included,
/// no coarse correction. The sequence's first iteration (its start) is not
/// timed, and a new sequence starts after [`Self::PER_SEQUENCE`] timed
/// ones: an iteration at a converged pose takes the plain step alone and
/// costs up to a third less, so timing a sequence that has converged
/// would shrink the unit on the meshes that converge first.
pub struct FineIterationClock {
    deformer: Deformer,
    left: usize,
}

impl FineIterationClock {
    /// Timed iterations per sequence from rest.
    pub const PER_SEQUENCE: usize = 11;

    /// A clock on `rest` with `params` (the solve's own).
    pub fn new(rest: Arc<Rest>, params: Params) -> Self {
        let mut deformer = Deformer::new(rest, params);
        deformer.set_levels(Levels::One);
        FineIterationClock { deformer, left: 0 }
    }

    /// The time of the next fine iteration towards `constraints`.
    pub fn time(
        &mut self,
        factor: &Factor,
        constraints: &Constraints,
    ) -> Result<Duration, DeformError> {
        if self.left == 0 {
            self.deformer.reset();
            self.deformer.step(factor, constraints, 1)?;
            self.left = Self::PER_SEQUENCE;
        }
        let t = Instant::now();
        std::hint::black_box(self.deformer.step(factor, constraints, 1)?);
        self.left -= 1;
        Ok(t.elapsed())
    }
}

/// The median of `v` (the mean of the two middle values for an even
/// count; NaN when empty): how benches and examples report timings.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let k = v.len();
    match k {
        0 => f64::NAN,
        _ if k % 2 == 1 => v[k / 2],
        _ => 0.5 * (v[k / 2 - 1] + v[k / 2]),
    }
}
