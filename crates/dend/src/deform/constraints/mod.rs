//! Constraint sets: fixed vertices and handle groups with rigid targets
//! (design.md §1), and the constraints JSON format (`api/constraints.schema.json`).
//!
//! - `transform.rs`: a handle's rigid target ([`RigidTransform`]) and the
//!   JSON's rotations ([`RotationSpec`]);
//! - `select.rs`: the JSON's vertex selectors ([`VertexSet`]) and [`select`],
//!   their selection on the rest mesh;
//! - `spec.rs`: the JSON itself ([`ConstraintsSpec`], [`HandleSpec`]) and its
//!   resolution into the validated set below, at rest or anchored at a pose;
//! - here: the validated set ([`Constraints`], [`HandleGroup`]).

mod groups;
mod select;
mod spec;
mod transform;

pub use crate::mesh::selection::{
    BoxSel, ConstraintsSpec, HandleSpec, RotationSpec, SphereSel, VertexSet,
};
pub use groups::{names_groups, resolve_groups};
pub use select::select;
pub use transform::RigidTransform;

use super::error::DeformError;
use crate::mesh::{Mesh, Point};

/// A handle group, resolved against a mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct HandleGroup {
    /// Name (unique within the set).
    pub name: String,
    /// Vertex indices, sorted, non-empty.
    pub vertices: Vec<u32>,
    /// Base positions the transform acts on (the rest positions unless the
    /// spec gave explicit ones), one per vertex, mesh units.
    pub base: Vec<Point>,
    /// Centroid of `base`.
    pub rest_centroid: Point,
    /// The current target transform.
    pub target: RigidTransform,
}

impl HandleGroup {
    /// Target positions of the handle's vertices (mesh units).
    pub fn target_positions(&self) -> impl Iterator<Item = (u32, Point)> + '_ {
        self.vertices
            .iter()
            .zip(&self.base)
            .map(|(&v, &p)| (v, self.target.apply(p)))
    }
}

/// A validated constraint set: fixed vertices and handle groups, pairwise
/// disjoint, every index in range.
#[derive(Debug, Clone, PartialEq)]
pub struct Constraints {
    /// Fixed vertices, sorted.
    pub fixed: Vec<u32>,
    /// Where each fixed vertex is held (mesh units; its rest position
    /// unless the spec or an anchoring pose said otherwise).
    pub fixed_at: Vec<Point>,
    /// Handle groups.
    pub handles: Vec<HandleGroup>,
}

impl Constraints {
    /// Builds and validates a constraint set from resolved index lists.
    /// `handles` are `(name, vertices, target)`; targets default to identity
    /// about the handle's rest centroid when `None`.
    pub fn new(
        mesh: &Mesh,
        fixed: Vec<u32>,
        handles: Vec<(String, Vec<u32>, Option<RigidTransform>)>,
    ) -> Result<Self, DeformError> {
        let n = mesh.num_vertices();
        let mut owner = vec![u32::MAX; n];
        let mut fixed = fixed;
        fixed.sort_unstable();
        fixed.dedup();
        for &v in &fixed {
            if v as usize >= n {
                return Err(DeformError::UnknownVertex {
                    index: v as u64,
                    vertices: n,
                });
            }
            owner[v as usize] = 0;
        }
        let mut groups = Vec::with_capacity(handles.len());
        for (k, (name, mut vs, target)) in handles.into_iter().enumerate() {
            vs.sort_unstable();
            vs.dedup();
            if vs.is_empty() {
                return Err(DeformError::EmptyHandle { name });
            }
            if groups.iter().any(|g: &HandleGroup| g.name == name) {
                return Err(DeformError::DuplicateHandle { name });
            }
            for &v in &vs {
                if v as usize >= n {
                    return Err(DeformError::UnknownVertex {
                        index: v as u64,
                        vertices: n,
                    });
                }
                if owner[v as usize] != u32::MAX {
                    return Err(DeformError::OverlappingSets {
                        vertex: v,
                        handle: name,
                    });
                }
                owner[v as usize] = k as u32 + 1;
            }
            let base: Vec<Point> = vs.iter().map(|&v| mesh.positions()[v as usize]).collect();
            let c = centroid(&base);
            groups.push(HandleGroup {
                name,
                vertices: vs,
                base,
                rest_centroid: c,
                target: target.unwrap_or_else(|| RigidTransform::identity(c)),
            });
        }
        if fixed.is_empty() && groups.is_empty() {
            return Err(DeformError::NoConstraints);
        }
        let fixed_at = fixed
            .iter()
            .map(|&v| mesh.positions()[v as usize])
            .collect();
        Ok(Constraints {
            fixed,
            fixed_at,
            handles: groups,
        })
    }

    /// Every constrained vertex (fixed and handles), sorted.
    pub fn constrained(&self) -> Vec<u32> {
        let mut all: Vec<u32> = self.fixed.clone();
        for h in &self.handles {
            all.extend_from_slice(&h.vertices);
        }
        all.sort_unstable();
        all
    }

    /// Index of the handle named `name`.
    pub fn handle_index(&self, name: &str) -> Option<usize> {
        self.handles.iter().position(|h| h.name == name)
    }
}

fn centroid(points: &[Point]) -> Point {
    let mut c = [0.0; 3];
    for p in points {
        for k in 0..3 {
            c[k] += p[k];
        }
    }
    let n = points.len().max(1) as f64;
    [c[0] / n, c[1] / n, c[2] / n]
}
