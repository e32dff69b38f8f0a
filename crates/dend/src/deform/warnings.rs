//! What a user should hear about a constraint set the solver accepts:
//! nothing fixed under a single handle (the mesh then moves rigidly), a
//! connected component nothing holds (it keeps its rest shape and place;
//! the factorisation adds a tiny diagonal shift), and stray constrained
//! vertices (a pick that left single vertices of a region among free or
//! other-region neighbours, which pull spikes out of the surface).

use serde::Serialize;

use super::constraints::Constraints;
use crate::mesh::Mesh;

/// Most stray vertices listed in a [`ConstraintWarning::StrayVertices`].
pub const STRAY_LISTED: usize = 16;

/// A property of a constraint set worth telling its user (the set is
/// valid: these are not errors).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, thiserror::Error)]
#[serde(tag = "code", rename_all = "snake_case")]
pub enum ConstraintWarning {
    /// One handle and no fixed vertex: the mesh follows the handle rigidly.
    #[error(
        "nothing is fixed: the whole mesh moves rigidly with the handle; fix a region to bend it"
    )]
    NothingFixed,
    /// A connected component without a constrained vertex.
    #[error("a part of {vertices} vertices has no fixed or handle vertex: it stays at rest, whatever the handles do")]
    UnconstrainedComponent {
        /// The component's label (`Topology::component`).
        component: u32,
        /// Its vertex count.
        vertices: usize,
    },
    /// Constrained vertices with neighbours, none of which is in their
    /// region (fixed, or the same handle).
    #[error("{count} constrained vertices are isolated from the rest of their region (for example vertex {}): stray picks pull spikes out of the surface", vertices.first().copied().unwrap_or(0))]
    StrayVertices {
        /// How many.
        count: usize,
        /// The first of them (at most [`STRAY_LISTED`]), increasing.
        vertices: Vec<u32>,
    },
}

impl Constraints {
    /// The [`ConstraintWarning`]s of this set on `mesh` (its rest mesh),
    /// in a fixed order: nothing fixed, unconstrained components by label,
    /// stray vertices. `O(V + E)`.
    pub fn warnings(&self, mesh: &Mesh) -> Vec<ConstraintWarning> {
        let topo = mesh.topology();
        let n = mesh.num_vertices();
        let mut out = Vec::new();
        if self.fixed.is_empty() && self.handles.len() == 1 {
            out.push(ConstraintWarning::NothingFixed);
        }
        // region of each vertex: 0 free, 1 fixed, 2 + k handle k
        let mut region = vec![0u32; n];
        for &v in &self.fixed {
            region[v as usize] = 1;
        }
        for (k, h) in self.handles.iter().enumerate() {
            for &v in &h.vertices {
                region[v as usize] = 2 + k as u32;
            }
        }
        let nc = topo.num_components();
        let mut size = vec![0usize; nc];
        let mut held = vec![false; nc];
        for (v, &r) in region.iter().enumerate() {
            if let Some(c) = topo.component(v) {
                size[c as usize] += 1;
                held[c as usize] |= r != 0;
            }
        }
        for c in 0..nc {
            if !held[c] {
                out.push(ConstraintWarning::UnconstrainedComponent {
                    component: c as u32,
                    vertices: size[c],
                });
            }
        }
        let mut count = 0;
        let mut listed = Vec::new();
        for v in 0..n {
            let ring = topo.ring(v);
            if region[v] != 0
                && !ring.is_empty()
                && ring.iter().all(|&u| region[u as usize] != region[v])
            {
                count += 1;
                if listed.len() < STRAY_LISTED {
                    listed.push(v as u32);
                }
            }
        }
        if count > 0 {
            out.push(ConstraintWarning::StrayVertices {
                count,
                vertices: listed,
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deform::factor::tests::grid;

    /// Row `r` of the `k × k` test grid.
    fn row(k: usize, r: usize) -> Vec<u32> {
        ((r * k) as u32..((r + 1) * k) as u32).collect()
    }

    #[test]
    fn a_clean_set_has_no_warning() {
        let m = grid(8);
        let c = Constraints::new(&m, row(8, 0), vec![("h".into(), row(8, 7), None)]).unwrap();
        assert_eq!(c.warnings(&m), vec![]);
    }

    #[test]
    fn one_handle_without_fixed_vertices_is_flagged() {
        let m = grid(8);
        let c = Constraints::new(&m, vec![], vec![("h".into(), row(8, 7), None)]).unwrap();
        assert_eq!(c.warnings(&m), vec![ConstraintWarning::NothingFixed]);
        // two handles bend the mesh between them: no warning
        let c = Constraints::new(
            &m,
            vec![],
            vec![("a".into(), row(8, 0), None), ("b".into(), row(8, 7), None)],
        )
        .unwrap();
        assert_eq!(c.warnings(&m), vec![]);
    }

    #[test]
    fn stray_picks_are_listed() {
        let m = grid(8);
        // vertex 3 * 8 + 4 alone in the middle, fixed; 5 * 8 + 2 alone, in
        // the handle
        let mut fixed = row(8, 0);
        fixed.push(28);
        let mut handle = row(8, 7);
        handle.push(42);
        let c = Constraints::new(&m, fixed, vec![("h".into(), handle, None)]).unwrap();
        assert_eq!(
            c.warnings(&m),
            vec![ConstraintWarning::StrayVertices {
                count: 2,
                vertices: vec![28, 42]
            }]
        );
        // a fixed vertex next to the fixed row is not stray
        let mut fixed = row(8, 0);
        fixed.push(8 + 3);
        let c = Constraints::new(&m, fixed, vec![("h".into(), row(8, 7), None)]).unwrap();
        assert_eq!(c.warnings(&m), vec![]);
    }

    #[test]
    fn a_loose_part_is_flagged() {
        // the grid plus a separate triangle far away
        let g = grid(4);
        let mut p = g.positions().to_vec();
        let mut t = g.triangles().to_vec();
        let base = p.len() as u32;
        p.extend([[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [10.0, 1.0, 0.0]]);
        t.push([base, base + 1, base + 2]);
        let m = Mesh::new(p, t).unwrap();
        let c = Constraints::new(&m, row(4, 0), vec![("h".into(), row(4, 3), None)]).unwrap();
        let w = c.warnings(&m);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(matches!(
            w[0],
            ConstraintWarning::UnconstrainedComponent { vertices: 3, .. }
        ));
        // the message reads as a sentence with the size
        assert!(w[0].to_string().contains("3 vertices"));
    }
}
