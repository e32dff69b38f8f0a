//! Vertex selectors of the constraints JSON ([`VertexSet`]: index lists,
//! boxes, spheres, asset groups) and [`select`], which picks them on the
//! rest mesh.

use crate::deform::error::DeformError;
use crate::mesh::asset::groups::GroupSel;
use crate::mesh::selection::VertexSet;
use crate::mesh::Mesh;

/// The vertices a [`VertexSet`] selects on the rest mesh, sorted; errors on
/// indices out of range and on NaN in selectors. Unreferenced vertices are
/// never selected by a box or a sphere.
pub fn select(set: &VertexSet, mesh: &Mesh) -> Result<Vec<u32>, DeformError> {
    let n = mesh.num_vertices();
    let referenced = |v: usize| !mesh.topology().ring(v).is_empty();
    let mut out: Vec<u32> = match set {
        VertexSet::Indices(ix) => {
            let mut out = Vec::with_capacity(ix.len().min(n));
            for &i in ix {
                if i >= n as u64 {
                    return Err(DeformError::UnknownVertex {
                        index: i,
                        vertices: n,
                    });
                }
                out.push(i as u32);
            }
            out
        }
        VertexSet::Box { bbox } => {
            if bbox.min.iter().chain(&bbox.max).any(|v| !v.is_finite()) {
                return Err(DeformError::NonFinite {
                    what: "box selector",
                });
            }
            (0..n)
                .filter(|&v| {
                    let p = mesh.positions()[v];
                    referenced(v) && (0..3).all(|k| p[k] >= bbox.min[k] && p[k] <= bbox.max[k])
                })
                .map(|v| v as u32)
                .collect()
        }
        VertexSet::Sphere { sphere } => {
            if !sphere
                .center
                .iter()
                .chain([&sphere.radius])
                .all(|v| v.is_finite())
                || sphere.radius < 0.0
            {
                return Err(DeformError::NonFinite {
                    what: "sphere selector",
                });
            }
            let r2 = sphere.radius * sphere.radius;
            (0..n)
                .filter(|&v| {
                    let p = mesh.positions()[v];
                    let d2: f64 = (0..3).map(|k| (p[k] - sphere.center[k]).powi(2)).sum();
                    referenced(v) && d2 <= r2
                })
                .map(|v| v as u32)
                .collect()
        }
        // a group needs the asset: resolved before, by Asset::resolve_groups
        VertexSet::Group(GroupSel { group }) => {
            return Err(DeformError::UnknownGroup {
                group: group.to_string(),
                available: Vec::new(),
            })
        }
        // so does a joint, and its skin
        VertexSet::Joint(j) => {
            return Err(DeformError::Rig(crate::rig::RigError::UnknownJoint {
                joint: j.joint.to_string(),
                available: Vec::new(),
            }))
        }
    };
    out.sort_unstable();
    out.dedup();
    Ok(out)
}
