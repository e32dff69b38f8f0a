//! The skeleton of a skinned asset ([`Asset::skeleton`]): joints in the
//! skin's order with their parents, children and heads, each asset
//! vertex's weights, and the joint regions constraints select.

use nalgebra::{Matrix4, Vector3};
use serde::{Deserialize, Serialize};

use super::error::RigError;
use crate::mesh::asset::groups::NameOrIndex;
use crate::mesh::asset::Asset;
use crate::mesh::io::gltf::{SkinData, SkinError};
use crate::mesh::selection::JointSel;

/// One joint.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// Its node's name, else `joint<k>` (`k` its index in the skin).
    pub name: String,
    /// Its node.
    pub node: usize,
    /// The nearest ancestor that is a joint.
    pub parent: Option<usize>,
    /// Joints whose parent it is.
    pub children: Vec<usize>,
    /// Its global transform at bind time, `IBM⁻¹`.
    pub bind: Matrix4<f64>,
    /// Its head (the origin of its node) at bind time, bind space.
    pub head: Vector3<f64>,
}

/// The skeleton of a skinned asset (module documentation).
#[derive(Debug, Clone)]
pub struct Skeleton {
    pub(super) skin: SkinData,
    pub(super) joints: Vec<Joint>,
    /// Joints with every parent before its children.
    pub(super) order: Vec<usize>,
    /// Per welded vertex: the joint it is dominated by (`None`: a vertex no
    /// solver triangle uses).
    dominant: Vec<Option<u32>>,
}

/// A joint as `GET /v1/meshes/{id}` and `dend info` list it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointInfo {
    /// Its name (what `{"joint": …}` selects by).
    pub name: String,
    /// Its index in the skin's joint list (`{"joint": 3}`).
    pub index: usize,
    /// Its glTF node.
    pub node: usize,
    /// Its parent joint's name (`None`: a root of the skeleton).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent: Option<String>,
    /// Its head (the joint's origin) in the mesh's bind space: where a
    /// gizmo for the joint sits.
    pub head: [f64; 3],
    /// Welded vertices it dominates (its region).
    pub vertices: usize,
    /// Those vertices, ascending (what `{"joint": …}` selects without
    /// children): a client paints the region without resolving a selector.
    #[serde(default)]
    pub region: Vec<u32>,
}

/// The skeleton as listed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkeletonInfo {
    /// The skin's index in the glTF document.
    pub skin: usize,
    /// Its joints, in the skin's order.
    pub joints: Vec<JointInfo>,
    /// Asset vertices whose weights did not sum to one and were normalised.
    #[serde(default)]
    pub renormalised_vertices: usize,
}

impl Asset {
    /// The asset's skeleton: [`RigError::NotGltf`] for other formats, and
    /// the skin's own errors ([`SkinError`]) when it is missing or broken.
    pub fn skeleton(&self) -> Result<Skeleton, RigError> {
        let g = self.gltf().ok_or(RigError::NotGltf {
            format: self.format(),
        })?;
        let skin = g.skin()?;
        Skeleton::new(skin, self)
    }
}

impl Skeleton {
    fn new(skin: SkinData, asset: &Asset) -> Result<Self, RigError> {
        let n = skin.joints.len();
        let mut joints: Vec<Joint> = skin
            .joints
            .iter()
            .enumerate()
            .map(|(k, j)| {
                let bind = j
                    .inverse_bind
                    .try_inverse()
                    .unwrap_or_else(Matrix4::identity);
                Joint {
                    name: j.name.clone().unwrap_or_else(|| format!("joint{k}")),
                    node: j.node,
                    parent: j.parent,
                    children: Vec::new(),
                    head: Vector3::new(bind[(0, 3)], bind[(1, 3)], bind[(2, 3)]),
                    bind,
                }
            })
            .collect();
        for k in 0..n {
            if let Some(p) = joints[k].parent {
                joints[p].children.push(k);
            }
        }
        // parents first (Kahn); what is left is a cycle
        let mut order: Vec<usize> = (0..n).filter(|&k| joints[k].parent.is_none()).collect();
        let mut at = 0;
        while at < order.len() {
            let k = order[at];
            order.extend(joints[k].children.iter().copied());
            at += 1;
        }
        if order.len() != n {
            return Err(SkinError::BadSkin {
                skin: skin.skin,
                message: "its joints' hierarchy has a cycle".into(),
            }
            .into());
        }
        let mesh = asset.mesh();
        let mut dominant: Vec<Option<u32>> = vec![None; mesh.num_vertices()];
        for (a, &w) in asset.to_welded().iter().enumerate() {
            let w = w as usize;
            if dominant[w].is_some() || mesh.topology().ring(w).is_empty() {
                continue;
            }
            dominant[w] = strongest(&skin.influences[a]);
        }
        Ok(Skeleton {
            skin,
            joints,
            order,
            dominant,
        })
    }

    /// The joints, in the skin's order.
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// Per asset vertex: `(joint, weight)`, weights summing to one.
    pub fn influences(&self) -> &[Vec<(u32, f64)>] {
        &self.skin.influences
    }

    /// The skin as read.
    pub fn skin(&self) -> &SkinData {
        &self.skin
    }

    /// The joints `joint` names (every joint of that name, or the one at
    /// that index), and with `with_children` their descendants.
    fn matching(&self, sel: &JointSel) -> Result<Vec<bool>, RigError> {
        let mut hit = vec![false; self.joints.len()];
        match &sel.joint {
            NameOrIndex::Index(i) if *i < self.joints.len() => hit[*i] = true,
            NameOrIndex::Index(_) => {}
            NameOrIndex::Name(n) => self
                .joints
                .iter()
                .zip(&mut hit)
                .for_each(|(j, h)| *h = j.name == *n),
        }
        if !hit.contains(&true) {
            return Err(RigError::UnknownJoint {
                joint: sel.joint.to_string(),
                available: self.joints.iter().map(|j| j.name.clone()).collect(),
            });
        }
        if sel.with_children {
            for &k in &self.order {
                if let Some(p) = self.joints[k].parent {
                    hit[k] |= hit[p];
                }
            }
        }
        Ok(hit)
    }

    /// The welded vertices `sel` selects, sorted (module documentation of
    /// [`crate::rig`]); [`RigError::UnknownJoint`] for a joint the skin
    /// does not have.
    pub fn joint_vertices(&self, sel: &JointSel) -> Result<Vec<u32>, RigError> {
        let hit = self.matching(sel)?;
        Ok(self
            .dominant
            .iter()
            .enumerate()
            .filter(|(_, d)| d.is_some_and(|j| hit[j as usize]))
            .map(|(v, _)| v as u32)
            .collect())
    }

    /// The skeleton as `GET /v1/meshes/{id}` lists it.
    pub fn info(&self) -> SkeletonInfo {
        let mut regions = vec![Vec::new(); self.joints.len()];
        for (v, j) in self.dominant.iter().enumerate() {
            if let Some(j) = j {
                regions[*j as usize].push(v as u32);
            }
        }
        SkeletonInfo {
            skin: self.skin.skin,
            joints: self
                .joints
                .iter()
                .zip(regions)
                .enumerate()
                .map(|(k, (j, region))| JointInfo {
                    name: j.name.clone(),
                    index: k,
                    node: j.node,
                    parent: j.parent.map(|p| self.joints[p].name.clone()),
                    head: [j.head.x, j.head.y, j.head.z],
                    vertices: region.len(),
                    region,
                })
                .collect(),
            renormalised_vertices: self.skin.renormalised,
        }
    }
}

/// The joint of largest weight (the first listed on a tie).
fn strongest(influences: &[(u32, f64)]) -> Option<u32> {
    let mut best: Option<(u32, f64)> = None;
    for &(j, w) in influences {
        match best {
            Some((bj, bw)) if bw > w || (bw == w && bj < j) => {}
            _ => best = Some((j, w)),
        }
    }
    best.map(|b| b.0)
}
