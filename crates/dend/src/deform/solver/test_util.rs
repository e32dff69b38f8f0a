//! Helpers shared by the solver's tests.

use nalgebra::{UnitQuaternion, Vector3};

use crate::deform::{Constraints, RigidTransform};
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

/// Fixed: the vertices with `x < x0`; handle: `x > x1`, moved by `t` and
/// turned by `r` about its centroid.
pub(super) fn x_edit(
    mesh: &Mesh,
    x0: Real,
    x1: Real,
    t: Point,
    r: UnitQuaternion<Real>,
) -> Constraints {
    let pick = |keep: &dyn Fn(Real) -> bool| -> Vec<u32> {
        (0..mesh.num_vertices() as u32)
            .filter(|&v| keep(mesh.positions()[v as usize][0]))
            .collect()
    };
    let fixed = pick(&|x| x < x0);
    let handle = pick(&|x| x > x1);
    let mut c = Constraints::new(mesh, fixed, vec![("h".into(), handle, None)]).unwrap();
    let pivot = c.handles[0].rest_centroid;
    c.handles[0].target = RigidTransform {
        rotation: r,
        translation: t,
        pivot,
    };
    c
}

/// `mesh` with every coordinate times `s`.
pub(super) fn scaled(mesh: &Mesh, s: Real) -> Mesh {
    Mesh::new(
        mesh.positions()
            .iter()
            .map(|p| [s * p[0], s * p[1], s * p[2]])
            .collect(),
        mesh.triangles().to_vec(),
    )
    .unwrap()
}

/// The representative edit of a patch over `[-1, 1]²` scaled by `s`: the
/// band `x < -0.8` fixed, the band `x > 0.8` lifted by 0.4, pulled in by
/// 0.3 and turned 50° about y (folding the patch over the fixed side).
pub(super) fn patch_edit(mesh: &Mesh, s: Real) -> Constraints {
    let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.9);
    x_edit(mesh, -0.8 * s, 0.8 * s, [-0.3 * s, 0.1 * s, 0.4 * s], r)
}

/// `m` as a dense matrix (duplicate entries summed).
pub(super) fn dense(m: &sprs::CsMat<Real>) -> nalgebra::DMatrix<Real> {
    let mut d = nalgebra::DMatrix::zeros(m.rows(), m.cols());
    for (v, (r, c)) in m.iter() {
        d[(r, c)] += *v;
    }
    d
}

/// Asserts that `got` is `expected` to `tol` of `expected`'s largest
/// entry, symmetric to the same tolerance, and positive semi-definite (no
/// eigenvalue below −1e-9 of that entry); `what` names the case.
pub(super) fn assert_same_symmetric_semidefinite(
    got: &nalgebra::DMatrix<Real>,
    expected: &nalgebra::DMatrix<Real>,
    tol: Real,
    what: &str,
) {
    let scale = expected.amax();
    assert!(scale > 0.0, "{what}: a zero matrix");
    let diff = (got - expected).amax();
    assert!(diff <= tol * scale, "{what}: {diff} of {scale}");
    let asym = (got - got.transpose()).amax();
    assert!(asym <= tol * scale, "{what}: asymmetry {asym}");
    let smallest = got.clone().symmetric_eigenvalues().min();
    assert!(
        smallest >= -1e-9 * scale,
        "{what}: eigenvalue {smallest} of {scale}"
    );
}
