//! Discrete differential operators on the rest mesh (design.md §2).
//!
//! [`Operators::new`] normalises a copy of the mesh (centroid at the origin,
//! mean edge length 1), and builds every operator on that copy once:
//! `Lbar` ([`cotmatrix`]), the mixed areas `A` ([`voronoi_areas`]),
//! `L = D Lbar` with `D = diag(1/A_i)`, `δ = L X`, the mean curvature `H`,
//! the angle-defect Gaussian curvature `K` and `G = max(H² - K, 0)`.
//! Curvatures on the normalised copy are dimensionless; [`Operators::scale`]
//! converts them back to the mesh's own units.

mod cotmatrix;
mod curvature;
mod voronoi_areas;

pub use cotmatrix::{cot, cotmatrix};
pub use curvature::{
    angle_defect, g_coefficient, laplacian_coordinates, mean_curvature, vertex_normals,
};
pub use voronoi_areas::voronoi_areas;

use sprs::CsMat;

use crate::mesh::{Mesh, Point, Real};

/// The rest-mesh operators of one mesh, built once and shared by every
/// session and constraint set on it. All quantities refer to the normalised
/// copy `X = (X_mesh - centroid) / scale`.
#[derive(Debug, Clone)]
pub struct Operators {
    /// Mean edge length of the original mesh: `X_mesh = scale · X + centroid`.
    pub scale: Real,
    /// Centroid of the original mesh's vertices.
    pub centroid: Point,
    /// Normalised rest positions `X`, `#V×3`.
    pub positions: Vec<Point>,
    /// `Lbar`, `#V×#V`, symmetric, `Lbar · 1 = 0` (libigl's `cotmatrix`).
    pub lbar: CsMat<Real>,
    /// Mixed Voronoi areas `A_i`, `#V` (0 for unreferenced vertices).
    pub area: Vec<Real>,
    /// `D = diag(1/A_i)` (0 for unreferenced vertices): `L = D Lbar`, so
    /// `Lᵀ x = Lbar (D x)`.
    pub inv_area: Vec<Real>,
    /// `L = D Lbar`, `#V×#V` (rows of unreferenced vertices are empty).
    pub l: CsMat<Real>,
    /// Laplacian coordinates `δ = L X`, `#V×3` (paper §5: `δ_i = 2 H_i n_i`).
    pub delta: Vec<Point>,
    /// Signed mean curvature `H_i` (positive on a sphere with outward normals).
    pub mean_curvature: Vec<Real>,
    /// Gaussian curvature `K_i = defect_i / A_i` (boundary rule in [`angle_defect`]).
    pub gaussian_curvature: Vec<Real>,
    /// `G_i = max(H_i² - K_i, 0)`.
    pub g: Vec<Real>,
}

impl Operators {
    /// Builds every operator of `mesh` on its normalised copy. O(#F).
    pub fn new(mesh: &Mesh) -> Self {
        let n = mesh.num_vertices();
        let refd: Vec<usize> = (0..n)
            .filter(|&i| !mesh.topology().ring(i).is_empty())
            .collect();
        let mut centroid = [0.0; 3];
        for &i in &refd {
            for (c, x) in centroid.iter_mut().zip(mesh.positions()[i]) {
                *c += x;
            }
        }
        for c in &mut centroid {
            *c /= refd.len().max(1) as Real;
        }
        let scale = mesh.mean_edge_length();
        let positions: Vec<Point> = mesh
            .positions()
            .iter()
            .map(|p| {
                [
                    (p[0] - centroid[0]) / scale,
                    (p[1] - centroid[1]) / scale,
                    (p[2] - centroid[2]) / scale,
                ]
            })
            .collect();
        let tris = mesh.triangles();
        let lbar = cotmatrix(&positions, tris);
        let area = voronoi_areas(&positions, tris);
        let inv_area: Vec<Real> = area
            .iter()
            .map(|&a| if a > 0.0 { 1.0 / a } else { 0.0 })
            .collect();
        let mut l = lbar.clone();
        for (i, mut row) in l.outer_iterator_mut().enumerate() {
            for (_, v) in row.iter_mut() {
                *v *= inv_area[i];
            }
        }
        let delta = laplacian_coordinates(&l, &positions);
        let normals = vertex_normals(&positions, tris);
        let mean_curvature = curvature::mean_curvature(&delta, &normals);
        let gaussian_curvature: Vec<Real> = angle_defect(&positions, tris, mesh.topology())
            .iter()
            .zip(&inv_area)
            .map(|(d, ia)| d * ia)
            .collect();
        let g = g_coefficient(&mean_curvature, &gaussian_curvature);
        Operators {
            scale,
            centroid,
            positions,
            lbar,
            area,
            inv_area,
            l,
            delta,
            mean_curvature,
            gaussian_curvature,
            g,
        }
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Maps a normalised point back to the mesh's own coordinates.
    pub fn denormalise(&self, p: Point) -> Point {
        [
            p[0] * self.scale + self.centroid[0],
            p[1] * self.scale + self.centroid[1],
            p[2] * self.scale + self.centroid[2],
        ]
    }

    /// Maps a point in the mesh's own coordinates to the normalised copy.
    pub fn normalise(&self, p: Point) -> Point {
        [
            (p[0] - self.centroid[0]) / self.scale,
            (p[1] - self.centroid[1]) / self.scale,
            (p[2] - self.centroid[2]) / self.scale,
        ]
    }
}
