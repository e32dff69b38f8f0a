//! Measurements of deformation quality used by the paper-reproduction tests
//! and reports (design.md §10): cross-section area and twist along a bar, and
//! the bending angle along a bent cylinder.

use crate::mesh::{sub, Point};

/// Per-slab figures of a bar deformed about its long axis `z`.
#[derive(Debug, Clone, PartialEq)]
pub struct SlabFigures {
    /// Mean rest `z` of each slab's vertices (where its twist is measured).
    pub z: Vec<f64>,
    /// Cross-section area relative to rest, per slab.
    pub area_ratio: Vec<f64>,
    /// Twist angle in degrees about the slab's axis, per slab.
    pub twist_deg: Vec<f64>,
}

impl SlabFigures {
    /// The smallest area ratio.
    pub fn min_area(&self) -> f64 {
        self.area_ratio
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min)
    }

    /// Largest deviation (degrees) of the twist from the linear ramp between
    /// 0 at `z0` and `total_deg` at `z1`.
    pub fn twist_deviation(&self, z0: f64, z1: f64, total_deg: f64) -> f64 {
        self.z
            .iter()
            .zip(&self.twist_deg)
            .map(|(&z, &t)| (t - total_deg * (z - z0) / (z1 - z0)).abs())
            .fold(0.0, f64::max)
    }
}

/// Cuts the rest mesh into `slabs` equal slabs along `z` between `z0` and
/// `z1`, and measures each slab in the pose: the area of the convex hull of
/// its vertices projected on the plane orthogonal to the local axis (the
/// direction between neighbouring slab centroids), relative to the same at
/// rest; and the mean rotation angle of the vertices about that axis,
/// relative to rest, unwrapped along the bar (degrees, right-hand about +z).
pub fn bar_slabs(rest: &[Point], pose: &[Point], z0: f64, z1: f64, slabs: usize) -> SlabFigures {
    let members: Vec<Vec<usize>> = (0..slabs)
        .map(|s| {
            let a = z0 + (z1 - z0) * s as f64 / slabs as f64;
            let b = z0 + (z1 - z0) * (s + 1) as f64 / slabs as f64;
            (0..rest.len())
                .filter(|&i| rest[i][2] >= a && rest[i][2] < b)
                .collect()
        })
        .collect();
    let centroid = |pts: &[Point], ix: &[usize]| {
        let mut c = [0.0; 3];
        for &i in ix {
            for k in 0..3 {
                c[k] += pts[i][k];
            }
        }
        let n = ix.len().max(1) as f64;
        [c[0] / n, c[1] / n, c[2] / n]
    };
    let rest_c: Vec<Point> = members.iter().map(|m| centroid(rest, m)).collect();
    let pose_c: Vec<Point> = members.iter().map(|m| centroid(pose, m)).collect();
    let axis = |cs: &[Point], s: usize| {
        let (a, b) = (s.saturating_sub(1), (s + 1).min(cs.len() - 1));
        let d = sub(cs[b], cs[a]);
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if l > 0.0 {
            [d[0] / l, d[1] / l, d[2] / l]
        } else {
            [0.0, 0.0, 1.0]
        }
    };
    let mut z = Vec::new();
    let mut area_ratio = Vec::new();
    let mut twist = Vec::new();
    let mut prev = 0.0f64;
    for (s, m) in members.iter().enumerate() {
        if m.len() < 3 {
            continue;
        }
        let (ra, pa) = (axis(&rest_c, s), axis(&pose_c, s));
        let area_rest = hull_area(rest, m, rest_c[s], ra);
        let area_pose = hull_area(pose, m, pose_c[s], pa);
        // twist: rotate the pose's frame so that its axis matches the rest axis
        let (u0, v0) = frame(ra);
        let (u1, v1) = frame(pa);
        // the circular mean of the vertices' turns (a plain mean of angles
        // wrapped to (−π, π] averages +179° and −179° to 0)
        let (mut sin, mut cos) = (0.0, 0.0);
        for &i in m {
            let a = sub(rest[i], rest_c[s]);
            let b = sub(pose[i], pose_c[s]);
            let ang0 = dot(a, v0).atan2(dot(a, u0));
            let ang1 = dot(b, v1).atan2(dot(b, u1));
            let d = ang1 - ang0;
            sin += d.sin();
            cos += d.cos();
        }
        let mut t = sin.atan2(cos).to_degrees();
        // unwrap along the bar
        while t - prev > 180.0 {
            t -= 360.0;
        }
        while t - prev < -180.0 {
            t += 360.0;
        }
        prev = t;
        // where the slab's vertices are: a slab holds one ring of the bar
        // or two, anywhere in it, and its twist is theirs (the slab's centre
        // put a linear twist up to half a slab's turn off its own ramp)
        z.push(rest_c[s][2]);
        area_ratio.push(area_pose / area_rest);
        twist.push(t);
    }
    SlabFigures {
        z,
        area_ratio,
        twist_deg: twist,
    }
}

fn dot(a: Point, b: Point) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// An orthonormal frame `(u, v)` of the plane orthogonal to `n`, continuous
/// around `n = +z` (so angles about z are comparable between rest and pose).
fn frame(n: Point) -> (Point, Point) {
    // project x onto the plane; fall back to y when n ≈ ±x
    let e = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let d = dot(e, n);
    let mut u = [e[0] - d * n[0], e[1] - d * n[1], e[2] - d * n[2]];
    let l = dot(u, u).sqrt();
    u = [u[0] / l, u[1] / l, u[2] / l];
    let v = [
        n[1] * u[2] - n[2] * u[1],
        n[2] * u[0] - n[0] * u[2],
        n[0] * u[1] - n[1] * u[0],
    ];
    (u, v)
}

/// Area of the 2D convex hull of `pts[ix]` projected on the plane through
/// `c` orthogonal to `n`.
fn hull_area(pts: &[Point], ix: &[usize], c: Point, n: Point) -> f64 {
    let (u, v) = frame(n);
    let mut q: Vec<(f64, f64)> = ix
        .iter()
        .map(|&i| {
            let d = sub(pts[i], c);
            (dot(d, u), dot(d, v))
        })
        .collect();
    q.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let crossz = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut hull: Vec<(f64, f64)> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(q.iter())
        } else {
            Box::new(q.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && crossz(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    let m = hull.len();
    (0..m)
        .map(|k| {
            let (a, b) = (hull[k], hull[(k + 1) % m]);
            a.0 * b.1 - a.1 * b.0
        })
        .sum::<f64>()
        .abs()
        / 2.0
}

/// Bending of a cylinder along its rest axis `z`: the angle (degrees) between
/// consecutive slab axes, per slab, and its coefficient of variation.
pub fn bend_angles(
    rest: &[Point],
    pose: &[Point],
    z0: f64,
    z1: f64,
    slabs: usize,
) -> (Vec<f64>, f64) {
    let cents: Vec<Point> = (0..slabs)
        .filter_map(|s| {
            let a = z0 + (z1 - z0) * s as f64 / slabs as f64;
            let b = z0 + (z1 - z0) * (s + 1) as f64 / slabs as f64;
            let ix: Vec<usize> = (0..rest.len())
                .filter(|&i| rest[i][2] >= a && rest[i][2] < b)
                .collect();
            if ix.is_empty() {
                return None;
            }
            let mut c = [0.0; 3];
            for &i in &ix {
                for k in 0..3 {
                    c[k] += pose[i][k];
                }
            }
            Some([
                c[0] / ix.len() as f64,
                c[1] / ix.len() as f64,
                c[2] / ix.len() as f64,
            ])
        })
        .collect();
    let dirs: Vec<Point> = cents.windows(2).map(|w| sub(w[1], w[0])).collect();
    let angles: Vec<f64> = dirs
        .windows(2)
        .map(|w| {
            let c = dot(w[0], w[1]) / (dot(w[0], w[0]).sqrt() * dot(w[1], w[1]).sqrt());
            c.clamp(-1.0, 1.0).acos().to_degrees()
        })
        .collect();
    let mean = angles.iter().sum::<f64>() / angles.len().max(1) as f64;
    let var = angles.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / angles.len().max(1) as f64;
    let cv = if mean > 0.0 { var.sqrt() / mean } else { 0.0 };
    (angles, cv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::gen::{generate, Shape, ShapeSpec};

    /// The generated bar (z from 0 to 7), each vertex turned about the z axis
    /// by `total_deg × z / 7`.
    fn twisted_bar(total_deg: f64) -> (Vec<Point>, Vec<Point>) {
        let m = generate(&ShapeSpec::default_for(Shape::Bar)).unwrap();
        let rest = m.positions().to_vec();
        let z1 = rest.iter().map(|p| p[2]).fold(f64::MIN, f64::max);
        let pose = rest
            .iter()
            .map(|p| {
                let a = (total_deg * p[2] / z1).to_radians();
                let (s, c) = a.sin_cos();
                [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]
            })
            .collect();
        (rest, pose)
    }

    #[test]
    fn a_linear_twist_measures_as_its_ramp_past_half_a_turn() {
        // 300° takes slabs through ±180°, where the vertices' turns wrap
        for total in [135.0, -135.0, 300.0, 420.0] {
            let (rest, pose) = twisted_bar(total);
            let z1 = rest.iter().map(|p| p[2]).fold(f64::MIN, f64::max);
            let fig = bar_slabs(&rest, &pose, 0.0, z1, 20);
            assert_eq!(fig.twist_deg.len(), 20);
            // each slab's turn is the mean of its vertices' turns
            for (s, &t) in fig.twist_deg.iter().enumerate() {
                let (a, b) = (z1 * s as f64 / 20.0, z1 * (s + 1) as f64 / 20.0);
                let zs: Vec<f64> = rest
                    .iter()
                    .map(|p| p[2])
                    .filter(|&z| z >= a && z < b)
                    .collect();
                let want = total * zs.iter().sum::<f64>() / zs.len() as f64 / z1;
                // the circular and the plain mean of turns within 1/20 of
                // the twist differ by far less than a degree
                assert!((t - want).abs() < 0.05, "{total}: slab {s}: {t} vs {want}");
            }
            // measured where the slabs' vertices are, an exact ramp is on
            // its ramp (at the slabs' centres it was up to 3.4° off at 135°)
            let dev = fig.twist_deviation(0.0, z1, total);
            assert!(dev < 0.05, "{total}: dev {dev}");
            assert!(
                (fig.min_area() - 1.0).abs() < 1e-9,
                "{total}: area {}",
                fig.min_area()
            );
        }
    }

    #[test]
    fn an_untwisted_bar_measures_zero_twist_and_full_area() {
        let (rest, _) = twisted_bar(0.0);
        let fig = bar_slabs(&rest, &rest, 0.0, 7.0, 10);
        assert!(fig.twist_deg.iter().all(|t| t.abs() < 1e-12));
        assert!(fig.area_ratio.iter().all(|a| (a - 1.0).abs() < 1e-12));
    }
}
