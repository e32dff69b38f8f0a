//! The skin of a glTF asset as data ([`GltfAsset::skin`]): its joints
//! (nodes, hierarchy, inverse bind matrices, rest transforms) and each asset
//! vertex's influences (`JOINTS_n`/`WEIGHTS_n`), checked.
//!
//! glTF 2.0 §3.7.3 (skins): a skinned vertex is placed at
//! `Σ_k w_k · G(joint_k) · IBM_k · v`, `G` the joint node's global transform
//! and `IBM` its inverse bind matrix; the mesh node's own transform is
//! ignored. Weights are meant to sum to one: a vertex whose weights do not
//! (by more than [`WEIGHT_SUM_TOLERANCE`]) is normalised, and the skin says
//! how many were ([`SkinData::renormalised`]).

use gltf::accessor::{DataType, Dimensions};
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};
use thiserror::Error;

use super::accessor::{locate, Located};
use super::asset::GltfAsset;

/// How far a vertex's weights may sum from one before it is normalised and
/// counted in [`SkinData::renormalised`]: the glTF validator's own
/// tolerance for unsigned-normalised weights is of this order (a byte's
/// step is 1/255 ≈ 4e-3 per weight).
pub const WEIGHT_SUM_TOLERANCE: f64 = 2e-3;

/// Why an asset's skin cannot be used as a rig.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum SkinError {
    /// No deformed mesh of the scene has a skin. Fix: export the asset with
    /// its armature (glTF `skins`, `JOINTS_0`, `WEIGHTS_0`).
    #[error(
        "the asset is not skinned: no mesh of its scene has a skin (export it with its armature)"
    )]
    NotSkinned,
    /// The scene's meshes use more than one skin, or some are skinned and
    /// others are not: one pose cannot be fitted to two rigs. Fix: join the
    /// meshes under one armature.
    #[error("the scene's meshes use {skins} skins{} (one rig is fitted at a time: join them under one armature)", if *.unskinned > 0 { format!(" and {} meshes are not skinned", .unskinned) } else { String::new() })]
    SeveralSkins {
        /// Distinct skins used by the scene's meshes.
        skins: usize,
        /// Deformed meshes without a skin.
        unskinned: usize,
    },
    /// A skinned primitive lacks its joints or weights, or they are of a
    /// type glTF does not allow.
    #[error("skinned mesh {mesh} primitive {primitive}: {message}")]
    BadAttributes {
        /// The mesh.
        mesh: usize,
        /// The primitive.
        primitive: usize,
        /// What is wrong.
        message: String,
    },
    /// A vertex names a joint past the skin's joint list.
    #[error("skin {skin}: vertex {vertex} names joint {joint}, the skin has {joints}")]
    JointOutOfRange {
        /// The skin.
        skin: usize,
        /// The asset vertex.
        vertex: usize,
        /// The joint index it names.
        joint: usize,
        /// The skin's joint count.
        joints: usize,
    },
    /// A vertex whose weights are all zero, negative or not finite: it
    /// follows no joint.
    #[error(
        "skin {skin}: vertex {vertex} has no usable weight (all zero, negative or not finite)"
    )]
    NoWeight {
        /// The skin.
        skin: usize,
        /// The asset vertex.
        vertex: usize,
    },
    /// The skin's joints or inverse bind matrices are malformed (a joint
    /// listed twice, a singular or non-finite bind matrix, a count that
    /// differs from the joint count).
    #[error("skin {skin}: {message}")]
    BadSkin {
        /// The skin.
        skin: usize,
        /// What is wrong.
        message: String,
    },
}

/// One vertex's `(joint, weight)` pairs.
pub type Influences = Vec<(u32, f64)>;

/// A node's local transform as translation, rotation and scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trs {
    /// Translation.
    pub translation: Vector3<f64>,
    /// Rotation.
    pub rotation: UnitQuaternion<f64>,
    /// Scale.
    pub scale: Vector3<f64>,
}

impl Trs {
    /// `T · R · S` as a matrix (glTF 2.0 §3.5.3).
    pub fn matrix(&self) -> Matrix4<f64> {
        Matrix4::new_translation(&self.translation)
            * self.rotation.to_homogeneous()
            * Matrix4::new_nonuniform_scaling(&self.scale)
    }
}

/// One joint of a skin.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinJoint {
    /// The joint's node.
    pub node: usize,
    /// The node's name.
    pub name: Option<String>,
    /// The node's parent node, if any.
    pub parent_node: Option<usize>,
    /// The nearest ancestor node that is a joint of this skin, as an index
    /// into [`SkinData::joints`].
    pub parent: Option<usize>,
    /// The node's local transform as the file has it.
    pub rest: Trs,
    /// The node's global transform in the file's rest scene.
    pub rest_global: Matrix4<f64>,
    /// The inverse bind matrix (identity when the skin has none).
    pub inverse_bind: Matrix4<f64>,
}

/// A skin, and the influences of the asset's vertices.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinData {
    /// The skin's index in the document.
    pub skin: usize,
    /// Its joints, in the skin's order (the `JOINTS_n` numbering).
    pub joints: Vec<SkinJoint>,
    /// Global transforms of every node of the document in the rest scene
    /// (nodes outside any hierarchy: their own local transform).
    pub node_globals: Vec<Matrix4<f64>>,
    /// Each node's parent node.
    pub node_parents: Vec<Option<usize>>,
    /// Each node's local transform.
    pub node_locals: Vec<Trs>,
    /// Per asset vertex: `(joint, weight)` with weight > 0, summing to one.
    pub influences: Vec<Influences>,
    /// Vertices whose weights did not sum to one and were normalised.
    pub renormalised: usize,
}

fn trs_of(node: &gltf::Node<'_>) -> Trs {
    let (t, r, s) = node.transform().decomposed();
    let q = Quaternion::new(
        f64::from(r[3]),
        f64::from(r[0]),
        f64::from(r[1]),
        f64::from(r[2]),
    );
    Trs {
        translation: Vector3::new(f64::from(t[0]), f64::from(t[1]), f64::from(t[2])),
        rotation: UnitQuaternion::from_quaternion(q),
        scale: Vector3::new(f64::from(s[0]), f64::from(s[1]), f64::from(s[2])),
    }
}

fn matrix_of(node: &gltf::Node<'_>) -> Matrix4<f64> {
    let m = node.transform().matrix();
    Matrix4::from_fn(|r, c| f64::from(m[c][r]))
}

/// Reads component `k` of element `i` of a `u8`/`u16`/`f32` VEC4 accessor,
/// normalised integers mapped to `[0, 1]` when `normalized`.
fn component(loc: &Located, buffers: &[Vec<u8>], i: usize, k: usize, normalized: bool) -> f64 {
    let b = &buffers[loc.buffer];
    match loc.data_type {
        DataType::U8 => {
            let v = f64::from(b[loc.start + i * loc.stride + k]);
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        DataType::U16 => {
            let at = loc.start + i * loc.stride + 2 * k;
            let v = f64::from(u16::from_le_bytes([b[at], b[at + 1]]));
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        _ => {
            let at = loc.start + i * loc.stride + 4 * k;
            f64::from(f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]))
        }
    }
}

impl GltfAsset {
    /// The document model again (it was validated when the asset was read).
    pub(super) fn document(&self) -> Option<gltf::Document> {
        let mut root: gltf::json::Root = serde_json::from_value(self.json.clone()).ok()?;
        root.extensions_required.clear();
        gltf::Document::from_json(root).ok()
    }

    /// The skin every deformed mesh uses, with its joints and the
    /// influences of every asset vertex (see the module documentation).
    pub fn skin(&self) -> Result<SkinData, SkinError> {
        let doc = self.document().ok_or(SkinError::NotSkinned)?;
        let nodes: Vec<gltf::Node<'_>> = doc.nodes().collect();
        let mut skins: Vec<usize> = Vec::new();
        let mut unskinned = 0;
        for b in &self.blocks {
            match nodes[b.node].skin() {
                Some(s) if !skins.contains(&s.index()) => skins.push(s.index()),
                Some(_) => {}
                None => unskinned += 1,
            }
        }
        let skin_index = match (skins.len(), unskinned) {
            (0, _) => return Err(SkinError::NotSkinned),
            (1, 0) => skins[0],
            (n, u) => {
                return Err(SkinError::SeveralSkins {
                    skins: n,
                    unskinned: u,
                })
            }
        };
        let Some(skin) = doc.skins().nth(skin_index) else {
            return Err(SkinError::NotSkinned);
        };
        let bad = |message: String| SkinError::BadSkin {
            skin: skin_index,
            message,
        };
        // the hierarchy and rest globals of every node
        let mut node_parents = vec![None; nodes.len()];
        for n in &nodes {
            for c in n.children() {
                node_parents[c.index()] = Some(n.index());
            }
        }
        let node_locals: Vec<Trs> = nodes.iter().map(trs_of).collect();
        let mut node_globals: Vec<Option<Matrix4<f64>>> = vec![None; nodes.len()];
        for start in 0..nodes.len() {
            let mut chain = vec![start];
            while let Some(p) = node_parents[*chain.last().unwrap_or(&start)] {
                if node_globals[p].is_some() || chain.contains(&p) {
                    break;
                }
                chain.push(p);
            }
            for &n in chain.iter().rev() {
                let parent = node_parents[n].and_then(|p| node_globals[p]);
                let local = matrix_of(&nodes[n]);
                node_globals[n] = Some(parent.map_or(local, |p| p * local));
            }
        }
        let node_globals: Vec<Matrix4<f64>> = node_globals
            .into_iter()
            .map(|m| m.unwrap_or_else(Matrix4::identity))
            .collect();
        let joint_nodes: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        if joint_nodes.is_empty() {
            return Err(bad("the skin has no joints".into()));
        }
        for (k, n) in joint_nodes.iter().enumerate() {
            if joint_nodes[..k].contains(n) {
                return Err(bad(format!("node {n} is listed twice among its joints")));
            }
        }
        let ibms = self.inverse_binds(&skin, joint_nodes.len(), skin_index)?;
        let joints = joint_nodes
            .iter()
            .zip(ibms)
            .map(|(&n, inverse_bind)| {
                let mut up = node_parents[n];
                let mut parent = None;
                // (bounded: a hierarchy with a cycle is not walked forever)
                for _ in 0..nodes.len() {
                    let Some(p) = up else { break };
                    if let Some(j) = joint_nodes.iter().position(|&x| x == p) {
                        parent = Some(j);
                        break;
                    }
                    up = node_parents[p];
                }
                SkinJoint {
                    node: n,
                    name: nodes[n].name().map(str::to_owned),
                    parent_node: node_parents[n],
                    parent,
                    rest: node_locals[n],
                    rest_global: node_globals[n],
                    inverse_bind,
                }
            })
            .collect();
        let (influences, renormalised) = self.influences(&nodes, skin_index, joint_nodes.len())?;
        Ok(SkinData {
            skin: skin_index,
            joints,
            node_globals,
            node_parents,
            node_locals,
            influences,
            renormalised,
        })
    }

    /// The skin's inverse bind matrices (identity without an accessor).
    fn inverse_binds(
        &self,
        skin: &gltf::Skin<'_>,
        joints: usize,
        index: usize,
    ) -> Result<Vec<Matrix4<f64>>, SkinError> {
        let bad = |message: String| SkinError::BadSkin {
            skin: index,
            message,
        };
        let Some(acc) = skin.inverse_bind_matrices() else {
            return Ok(vec![Matrix4::identity(); joints]);
        };
        let loc = locate(
            &acc,
            &self.buffers,
            Dimensions::Mat4,
            &[DataType::F32],
            "inverseBindMatrices",
        )
        .map_err(|e| bad(e.to_string()))?;
        if loc.count != joints {
            return Err(bad(format!(
                "{} inverse bind matrices for {joints} joints",
                loc.count
            )));
        }
        let m: Vec<[f32; 16]> = super::accessor::read_f32::<16>(&loc, &self.buffers);
        m.iter()
            .enumerate()
            .map(|(k, m)| {
                let mat = Matrix4::from_fn(|r, c| f64::from(m[c * 4 + r]));
                let ok = mat.iter().all(|v| v.is_finite()) && mat.try_inverse().is_some();
                if ok {
                    Ok(mat)
                } else {
                    Err(bad(format!(
                        "the inverse bind matrix of joint {k} is singular or not finite"
                    )))
                }
            })
            .collect()
    }

    /// Per asset vertex, its normalised influences; and how many vertices
    /// needed normalising.
    fn influences(
        &self,
        nodes: &[gltf::Node<'_>],
        skin: usize,
        joints: usize,
    ) -> Result<(Vec<Influences>, usize), SkinError> {
        let mut out = vec![Vec::new(); self.positions.len()];
        let mut renormalised = 0;
        for b in &self.blocks {
            let Some(mesh) = nodes[b.node].mesh() else {
                continue;
            };
            let Some(prim) = mesh.primitives().find(|p| {
                p.get(&gltf::Semantic::Positions)
                    .is_some_and(|a| a.index() == b.position.accessor)
            }) else {
                continue;
            };
            let at = |message: String| SkinError::BadAttributes {
                mesh: mesh.index(),
                primitive: prim.index(),
                message,
            };
            let mut sets = Vec::new();
            for set in 0.. {
                let (j, w) = (
                    prim.get(&gltf::Semantic::Joints(set)),
                    prim.get(&gltf::Semantic::Weights(set)),
                );
                match (j, w) {
                    (None, None) => break,
                    (Some(j), Some(w)) => {
                        let jl = locate(
                            &j,
                            &self.buffers,
                            Dimensions::Vec4,
                            &[DataType::U8, DataType::U16],
                            "JOINTS",
                        )
                        .map_err(|e| at(e.to_string()))?;
                        let wl = locate(
                            &w,
                            &self.buffers,
                            Dimensions::Vec4,
                            &[DataType::U8, DataType::U16, DataType::F32],
                            "WEIGHTS",
                        )
                        .map_err(|e| at(e.to_string()))?;
                        if w.data_type() != DataType::F32 && !w.normalized() {
                            return Err(at(format!(
                                "WEIGHTS_{set} is an integer accessor that is not normalized"
                            )));
                        }
                        sets.push((jl, wl));
                    }
                    (Some(_), None) => {
                        return Err(at(format!("JOINTS_{set} without WEIGHTS_{set}")))
                    }
                    (None, Some(_)) => {
                        return Err(at(format!("WEIGHTS_{set} without JOINTS_{set}")))
                    }
                }
            }
            if sets.is_empty() {
                return Err(at("the mesh has a skin but no JOINTS_0/WEIGHTS_0".into()));
            }
            for k in 0..b.position.count {
                let v = b.first + k;
                let mut inf: Vec<(u32, f64)> = Vec::with_capacity(4);
                for (jl, wl) in &sets {
                    for c in 0..4 {
                        let w = component(wl, &self.buffers, k, c, true);
                        if w.is_nan() || w <= 0.0 || !w.is_finite() {
                            continue;
                        }
                        let j = component(jl, &self.buffers, k, c, false) as usize;
                        if j >= joints {
                            return Err(SkinError::JointOutOfRange {
                                skin,
                                vertex: v,
                                joint: j,
                                joints,
                            });
                        }
                        match inf.iter_mut().find(|(x, _)| *x as usize == j) {
                            Some(e) => e.1 += w,
                            None => inf.push((j as u32, w)),
                        }
                    }
                }
                let sum: f64 = inf.iter().map(|e| e.1).sum();
                if sum.is_nan() || sum <= 0.0 {
                    return Err(SkinError::NoWeight { skin, vertex: v });
                }
                if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
                    renormalised += 1;
                }
                inf.iter_mut().for_each(|e| e.1 /= sum);
                out[v] = inf;
            }
        }
        Ok((out, renormalised))
    }
}
