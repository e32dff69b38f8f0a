//! Helpers shared by the solver's tests.

use crate::deform::Constraints;
use crate::mesh::gen::creature_constraints;
use crate::mesh::{norm, sub, Mesh, Point, Real};

/// The largest distance between corresponding points of two poses.
pub(super) fn max_dist(a: &[Point], b: &[Point]) -> Real {
    a.iter()
        .zip(b)
        .map(|(&p, &q)| norm(sub(p, q)))
        .fold(0.0, Real::max)
}

/// The generated creature's edit (`creature_constraints`) with its first
/// handle moved by (0, 0.3, 0.4): targets off the rest positions.
pub(super) fn creature_moved(mesh: &Mesh) -> Constraints {
    let mut spec = creature_constraints(mesh);
    spec.handles[0].translate = Some([0.0, 0.3, 0.4]);
    spec.resolve(mesh).unwrap()
}
