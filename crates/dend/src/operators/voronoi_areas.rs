//! Mixed Voronoi areas (Meyer, Desbrun, Schröder & Barr 2003, "Discrete
//! differential-geometry operators for triangulated 2-manifolds", Fig. 4).

use crate::mesh::{cross, dot, norm, sub, Point, Real};

use super::cotmatrix::cot;

/// The mixed Voronoi area `A_i` of every vertex, `#V`.
///
/// Per triangle: if it is non-obtuse, each corner `i` gets its Voronoi share
/// `(|e_ij|² cot γ_k + |e_ik|² cot γ_j) / 8`; if it is obtuse, the obtuse
/// corner gets `area/2` and the other two `area/4`. The shares of a triangle
/// sum to its area, so `Σ A_i` is the surface area. Equal to libigl's
/// `massmatrix(V, F, MASSMATRIX_TYPE_VORONOI)` diagonal. Unreferenced
/// vertices get 0.
pub fn voronoi_areas(positions: &[Point], triangles: &[[u32; 3]]) -> Vec<Real> {
    let mut area = vec![0.0; positions.len()];
    for t in triangles {
        let p = t.map(|i| positions[i as usize]);
        let tri_area = 0.5 * norm(cross(sub(p[1], p[0]), sub(p[2], p[0])));
        // dot products at each corner: negative means obtuse
        let corner_dot = |k: usize| dot(sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
        let obtuse = (0..3).find(|&k| corner_dot(k) < 0.0);
        for k in 0..3 {
            let share = match obtuse {
                Some(o) if o == k => tri_area / 2.0,
                Some(_) => tri_area / 4.0,
                None => {
                    let (j, l) = ((k + 1) % 3, (k + 2) % 3);
                    let ej = sub(p[j], p[k]);
                    let el = sub(p[l], p[k]);
                    // edge k-j is opposite corner l; edge k-l opposite corner j
                    (dot(ej, ej) * cot(p[l], p[k], p[j]) + dot(el, el) * cot(p[j], p[k], p[l]))
                        / 8.0
                }
            };
            area[t[k] as usize] += share;
        }
    }
    area
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_triangle_splits_in_thirds() {
        let s = 3f64.sqrt();
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, s / 2.0, 0.0]];
        let a = voronoi_areas(&p, &[[0, 1, 2]]);
        let total = s / 4.0;
        for ai in a {
            assert!((ai - total / 3.0).abs() < 1e-15);
        }
    }

    #[test]
    fn obtuse_triangle_uses_half_and_quarters() {
        let p = vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.2, 0.0]];
        let a = voronoi_areas(&p, &[[0, 1, 2]]);
        let total = 0.2;
        assert!((a[2] - total / 2.0).abs() < 1e-15);
        assert!((a[0] - total / 4.0).abs() < 1e-15);
        assert!((a[1] - total / 4.0).abs() < 1e-15);
    }

    #[test]
    fn right_triangle_voronoi_shares_sum_to_area() {
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let a = voronoi_areas(&p, &[[0, 1, 2]]);
        // right angle at 0: circumcentre at the hypotenuse midpoint
        assert!((a[0] - 0.25).abs() < 1e-15);
        assert!((a[1] - 0.125).abs() < 1e-15);
        assert!((a[2] - 0.125).abs() < 1e-15);
    }
}
