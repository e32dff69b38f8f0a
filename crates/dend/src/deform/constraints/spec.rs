//! The constraints JSON (`api/constraints.schema.json`) as written
//! ([`ConstraintsSpec`], [`HandleSpec`]), its resolution against a mesh
//! into a validated [`Constraints`] (at rest or anchored at a pose), and
//! the anchored spec a session stores after a constraint edit.

use nalgebra::UnitQuaternion;

use super::{
    centroid, select, Constraints, ConstraintsSpec, HandleGroup, HandleSpec, RigidTransform,
};
use crate::deform::error::DeformError;
use crate::mesh::{Mesh, Point};

impl ConstraintsSpec {
    /// Selects the vertex sets on the rest mesh and validates the result.
    pub fn resolve(&self, mesh: &Mesh) -> Result<Constraints, DeformError> {
        self.resolve_at(mesh, None)
    }

    /// [`resolve`](Self::resolve), with the constrained vertices held where
    /// `pose` has them instead of at rest: fixed vertices stay at their
    /// posed positions, and handle transforms act on the posed positions
    /// (default pivot: their posed centroid). Explicit `fixed_positions`
    /// and handle `positions` still win. Vertex sets (boxes, spheres) are
    /// always selected on the rest mesh. This is how a constraint edit keeps
    /// the pose.
    pub fn resolve_at(
        &self,
        mesh: &Mesh,
        pose: Option<&[Point]>,
    ) -> Result<Constraints, DeformError> {
        if let Some(p) = pose {
            check_positions("(anchoring pose)", "anchoring pose", mesh.num_vertices(), p)?;
        }
        let fixed = select(&self.fixed, mesh)?;
        let mut handles = Vec::with_capacity(self.handles.len());
        for (k, h) in self.handles.iter().enumerate() {
            let name = h.name.clone().unwrap_or_else(|| format!("handle{k}"));
            handles.push((name, select(&h.vertices, mesh)?, None));
        }
        // one group per spec handle, in the spec's order
        let mut c = Constraints::new(mesh, fixed, handles)?;
        if let Some(pos) = &self.fixed_positions {
            check_positions("(fixed)", "fixed positions", c.fixed.len(), pos)?;
            c.fixed_at = pos.clone();
        } else if let Some(p) = pose {
            c.fixed_at = c.fixed.iter().map(|&v| p[v as usize]).collect();
        }
        for (g, spec) in c.handles.iter_mut().zip(&self.handles) {
            spec.place(g, pose)?;
        }
        Ok(c)
    }
}

impl HandleSpec {
    /// Sets a resolved group's base positions (explicit `positions`, else
    /// the pose's, else the rest ones `g` has) and its target transform.
    fn place(&self, g: &mut HandleGroup, pose: Option<&[Point]>) -> Result<(), DeformError> {
        if let Some(pos) = &self.positions {
            check_positions(&g.name, "handle positions", g.vertices.len(), pos)?;
            g.base = pos.clone();
            g.rest_centroid = centroid(&g.base);
        } else if let Some(p) = pose {
            g.base = g.vertices.iter().map(|&v| p[v as usize]).collect();
            g.rest_centroid = centroid(&g.base);
        }
        let pivot = self.pivot.unwrap_or(g.rest_centroid);
        let translation = self.translate.unwrap_or([0.0; 3]);
        if pivot.iter().chain(&translation).any(|v| !v.is_finite()) {
            return Err(DeformError::NonFinite {
                what: "handle transform",
            });
        }
        let rotation = match &self.rotate {
            Some(r) => r.to_quaternion()?,
            None => UnitQuaternion::identity(),
        };
        g.target = RigidTransform {
            rotation,
            translation,
            pivot,
        };
        Ok(())
    }
}

/// Explicit positions for `expected` vertices of `handle` (or of the fixed
/// set, or of the whole mesh): one each, all finite.
fn check_positions(
    handle: &str,
    what: &'static str,
    expected: usize,
    pos: &[Point],
) -> Result<(), DeformError> {
    if pos.len() != expected {
        return Err(DeformError::PositionsMismatch {
            handle: handle.into(),
            expected,
            got: pos.len(),
        });
    }
    if pos.iter().flatten().any(|v| !v.is_finite()) {
        return Err(DeformError::NonFinite { what });
    }
    Ok(())
}

impl ConstraintsSpec {
    /// This spec with the positions `c` holds its vertices at written out
    /// wherever they differ from the rest mesh's (`fixed_positions`, each
    /// handle's `positions`), so that [`resolve`](Self::resolve) on the rest
    /// mesh gives `c`'s vertex sets and bases again: what a session stores
    /// after a constraint edit that kept the pose. `c` must be this spec
    /// resolved on `mesh` (same vertex sets, same handle order).
    pub fn anchored(&self, mesh: &Mesh, c: &Constraints) -> ConstraintsSpec {
        let rest = mesh.positions();
        let differs =
            |vs: &[u32], at: &[Point]| vs.iter().zip(at).any(|(&v, p)| rest[v as usize] != *p);
        let mut out = self.clone();
        out.fixed_positions = differs(&c.fixed, &c.fixed_at).then(|| c.fixed_at.clone());
        for (h, g) in out.handles.iter_mut().zip(&c.handles) {
            if differs(&g.vertices, &g.base) {
                h.positions = Some(g.base.clone());
                // the pivot the resolution chose, kept explicit: a default
                // pivot is the centroid of the positions it acts on
                h.pivot.get_or_insert(g.target.pivot);
            }
        }
        out
    }
}

#[cfg(test)]
#[path = "spec_tests.rs"]
mod tests;
