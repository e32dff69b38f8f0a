//! Helpers shared by the solver's tests.

use crate::mesh::{norm, sub, Point, Real};

/// The largest distance between corresponding points of two poses.
pub(super) fn max_dist(a: &[Point], b: &[Point]) -> Real {
    a.iter()
        .zip(b)
        .map(|(&p, &q)| norm(sub(p, q)))
        .fold(0.0, Real::max)
}
