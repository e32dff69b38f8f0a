//! [`level_minima`]: each level's own minimum of the creature's edit is a
//! minimum of the level's model near the fine one, and the measure does not
//! depend on the unit of length.

use std::sync::Arc;

use nalgebra::{UnitQuaternion, Vector3};

use super::level_minima::{level_minima_with_detail, LevelMinima};
use super::test_util::scaled;
use crate::deform::{Params, Rest};
use crate::mesh::gen::{creature_constraints, generate, Shape, ShapeSpec};
use crate::mesh::Real;

/// [`level_minima`](super::level_minima::level_minima) of the 2,306-vertex
/// creature scaled by `s`, for its edit: feet fixed, the head moved up and
/// sideways and turned 40° about the vertical.
fn creature_minima(s: Real) -> LevelMinima {
    creature_minima_with_detail(s, 1.0)
}

/// [`creature_minima`] with each level's detail weight times `detail`
/// against the level above.
fn creature_minima_with_detail(s: Real, detail: Real) -> LevelMinima {
    let mut spec = ShapeSpec::default_for(Shape::Creature);
    spec.params.nu = Some(2);
    let mesh = scaled(&generate(&spec).unwrap(), s);
    let mut cs = creature_constraints(&mesh);
    cs.handles[0].translate = Some([0.0, 0.3 * s, 0.4 * s]);
    let mut c = cs.resolve(&mesh).unwrap();
    c.handles[0].target.rotation =
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 40f64.to_radians());
    let params = Params {
        tol: 1e-5,
        max_iters: 3000,
        ..Params::default()
    };
    level_minima_with_detail(&Arc::new(Rest::new(mesh).unwrap()), &params, &c, detail).unwrap()
}

/// Every solve converges; the level's own minimum is no higher in the
/// level's objective than the fine minimum's positions (it is the level's
/// minimum, in the same basin) and lies within 5 % of the diagonal of the
/// fine minimum (measured 1.4 %; a wrong map between the levels' vertices
/// puts it at the size of the mesh); and the same edit of the mesh scaled
/// by 37 gives the same iterations, the same distances over the diagonal
/// and the same objectives over the unit's square, to 1e-6.
#[test]
fn a_level_minimum_is_near_the_fine_one_in_any_unit() {
    let m = creature_minima(1.0);
    assert!(m.fine_converged, "{m:?}");
    assert!(!m.levels.is_empty(), "no levels: {m:?}");
    for (k, l) in m.levels.iter().enumerate() {
        assert!(l.converged, "level {k}: {l:?}");
        assert!(
            l.objective_own <= l.objective_at_fine * (1.0 + 1e-9),
            "level {k}: {l:?}"
        );
        assert!(l.max_over_diagonal < 0.05, "level {k}: {l:?}");
        assert!(
            l.rms_over_diagonal <= l.max_over_diagonal,
            "level {k}: {l:?}"
        );
    }
    let s = 37.0;
    let big = creature_minima(s);
    let close = |a: Real, b: Real| (a - b).abs() <= 1e-6 * a.abs().max(b.abs());
    assert_eq!(m.fine_iterations, big.fine_iterations);
    assert!(close(m.fine_objective, big.fine_objective / (s * s)));
    assert_eq!(m.levels.len(), big.levels.len());
    for (a, b) in m.levels.iter().zip(&big.levels) {
        assert_eq!((a.vertices, a.iterations), (b.vertices, b.iterations));
        assert!(
            close(a.max_over_diagonal, b.max_over_diagonal),
            "{a:?} {b:?}"
        );
        assert!(
            close(a.rms_over_diagonal, b.rms_over_diagonal),
            "{a:?} {b:?}"
        );
        assert!(
            close(a.objective_own, b.objective_own / (s * s)),
            "{a:?} {b:?}"
        );
        assert!(
            close(a.objective_at_fine, b.objective_at_fine / (s * s)),
            "{a:?} {b:?}"
        );
    }
}

/// A softer detail weight on the levels changes their models and nothing
/// of the fine one: the same fine solve (iterations and objective, bit for
/// bit), and on every level a lower own minimum, since the level's
/// objective is pointwise no higher with a smaller weight on its detail
/// term (`E₂ ≥ 0`), so its minimum is no higher either.
#[test]
fn a_softer_level_detail_weight_lowers_the_levels_minima_not_the_fine_one() {
    let plain = creature_minima(1.0);
    let soft = creature_minima_with_detail(1.0, 0.25);
    assert_eq!(soft.detail_scale, 0.25);
    assert_eq!(plain.fine_iterations, soft.fine_iterations);
    assert_eq!(
        plain.fine_objective.to_bits(),
        soft.fine_objective.to_bits()
    );
    assert_eq!(plain.levels.len(), soft.levels.len());
    for (k, (a, b)) in plain.levels.iter().zip(&soft.levels).enumerate() {
        assert_eq!(a.vertices, b.vertices);
        assert!(b.converged, "level {k}: {b:?}");
        assert!(
            b.objective_own < a.objective_own,
            "level {k}: soft {b:?} against {a:?}"
        );
    }
}
