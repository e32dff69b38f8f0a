//! Constraints that select vertices by the named parts of an asset
//! (`mesh::asset::groups`): a group resolves to the welded vertices of its
//! parts, or to [`DeformError::UnknownGroup`] listing the parts there are;
//! and by the joints of its skin (`crate::rig`): a joint resolves to its
//! region, or to [`DeformError::Rig`].

use crate::deform::error::DeformError;
use crate::mesh::asset::groups::{GroupRef, GroupSel};
use crate::mesh::asset::Asset;
use crate::mesh::io::gltf::SkinError;
use crate::mesh::selection::{ConstraintsSpec, VertexSet};
use crate::rig::{RigError, Skeleton};

impl Asset {
    /// The welded vertices `group` selects (sorted): the union of the
    /// matching parts' vertices; [`DeformError::UnknownGroup`] when no part
    /// matches.
    pub fn group_vertices(&self, group: &GroupRef) -> Result<Vec<u32>, DeformError> {
        self.matching_vertices(group)
            .ok_or_else(|| DeformError::UnknownGroup {
                group: group.to_string(),
                available: self.part_names(),
            })
    }

    /// `spec` with every `{"group": …}` and `{"joint": …}` vertex set
    /// replaced by the index list it selects on this asset; other sets are
    /// kept as they are.
    pub fn resolve_groups(&self, spec: &ConstraintsSpec) -> Result<ConstraintsSpec, DeformError> {
        resolve_groups(Some(self), spec)
    }
}

/// [`Asset::resolve_groups`] on `asset`; with
/// no asset (a mesh uploaded as JSON, OFF, STL or generated) any group is
/// [`DeformError::UnknownGroup`].
pub fn resolve_groups(
    asset: Option<&Asset>,
    spec: &ConstraintsSpec,
) -> Result<ConstraintsSpec, DeformError> {
    let mut skeleton: Option<Skeleton> = None;
    let mut resolve = |set: &VertexSet| -> Result<VertexSet, DeformError> {
        Ok(match (set, asset) {
            (VertexSet::Joint(j), Some(a)) => {
                let sk = match skeleton.take() {
                    Some(sk) => sk,
                    None => a.skeleton()?,
                };
                let vs = sk.joint_vertices(j)?;
                skeleton = Some(sk);
                VertexSet::Indices(vs.into_iter().map(u64::from).collect())
            }
            (VertexSet::Joint(_), None) => return Err(RigError::Skin(SkinError::NotSkinned).into()),
            (VertexSet::Group(GroupSel { group }), Some(a)) => VertexSet::Indices(
                a.group_vertices(group)?
                    .into_iter()
                    .map(u64::from)
                    .collect(),
            ),
            (VertexSet::Group(GroupSel { group }), None) => {
                return Err(DeformError::UnknownGroup {
                    group: group.to_string(),
                    available: Vec::new(),
                })
            }
            (other, _) => other.clone(),
        })
    };
    let mut out = spec.clone();
    out.fixed = resolve(&spec.fixed)?;
    for h in &mut out.handles {
        h.vertices = resolve(&h.vertices)?;
    }
    Ok(out)
}

/// Whether `spec` names a group or a joint anywhere (so resolving it needs
/// the asset).
pub fn names_groups(spec: &ConstraintsSpec) -> bool {
    std::iter::once(&spec.fixed)
        .chain(spec.handles.iter().map(|h| &h.vertices))
        .any(|s| matches!(s, VertexSet::Group(_) | VertexSet::Joint(_)))
}
