//! Poses written into a skinned document's joint nodes
//! ([`GltfAsset::export_skeleton`]): what a game pipeline animates.
//!
//! - **One pose** (`animation` off): each posed joint node gets the pose's
//!   translation, rotation and scale (a node stored as a `matrix` is
//!   rewritten as TRS), and the pose's corrective, if any, is a morph
//!   target of weight 1 on every deformed mesh, so the file opens posed.
//! - **An animation** (`animation` on): the nodes keep their rest TRS; one
//!   more animation, `poses`, has one keyframe per pose (pose `k` at
//!   `t = k` seconds, played in order, linear: quaternions are
//!   interpolated by slerp as glTF 2.0 §3.11 prescribes) keying every
//!   posed joint's rotation and translation, and, when the poses carry
//!   correctives, the deformed nodes' morph weights (pose `k`'s corrective
//!   alone at 1). Rotations of consecutive keyframes are kept on the same
//!   side of the quaternion sphere so they blend the short way.
//!
//! The correctives are written as [`GltfAsset::export_morph_targets`]
//! writes targets (bind-space deltas on the skinned primitives, named in
//! `extras.targetNames`); everything else is copied.

use std::collections::BTreeSet;

use serde_json::{json, Value};

use super::asset::{Container, GltfAsset};
use super::morph::push;
use super::morph::MorphTarget;

/// One joint node's local transform in a pose (`f32`, as glTF stores it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeTrs {
    /// The node.
    pub node: usize,
    /// Translation.
    pub translation: [f32; 3],
    /// Unit quaternion `[x, y, z, w]`.
    pub rotation: [f32; 4],
    /// Scale.
    pub scale: [f32; 3],
}

/// A pose of the skeleton: its joint nodes and its corrective.
#[derive(Debug, Clone)]
pub struct SkeletonPose {
    /// The pose's name (the corrective target's name).
    pub name: String,
    /// Every posed joint node.
    pub nodes: Vec<NodeTrs>,
    /// The corrective shape as a morph target (its `pose` is the bind
    /// pose plus the corrective), or `None` to leave it out.
    pub corrective: Option<MorphTarget>,
}

/// Writes `t` into the node object `node` as TRS, dropping a `matrix`.
fn set_trs(node: &mut Value, t: &NodeTrs) {
    if let Some(o) = node.as_object_mut() {
        o.remove("matrix");
        let _ = o.insert("translation".into(), json!(t.translation));
        let _ = o.insert("rotation".into(), json!(t.rotation));
        let _ = o.insert("scale".into(), json!(t.scale));
    }
}

impl GltfAsset {
    /// The document with `poses` in its joint nodes (module documentation),
    /// as `container`. Without `animation` only the first pose is written.
    pub fn export_skeleton(
        &self,
        poses: &[SkeletonPose],
        animation: bool,
        container: Container,
    ) -> Vec<u8> {
        let poses = if animation {
            poses
        } else {
            &poses[..poses.len().min(1)]
        };
        let rests = self.rest_trs();
        let rest = |n: usize| rests.get(n).copied();
        let targets: Vec<MorphTarget> = poses.iter().filter_map(|p| p.corrective.clone()).collect();
        let mut doc = self.with_morph_targets(&targets);
        // joint nodes stored as a matrix become TRS (animations need TRS)
        let posed: BTreeSet<usize> = poses
            .iter()
            .flat_map(|p| p.nodes.iter().map(|n| n.node))
            .collect();
        for &n in &posed {
            if let Some(rest) = rest(n) {
                if let Some(node) = doc.json.pointer_mut(&format!("/nodes/{n}")) {
                    if node.get("matrix").is_some() {
                        set_trs(node, &rest);
                    }
                }
            }
        }
        if !animation {
            if let Some(p) = poses.first() {
                for t in &p.nodes {
                    if let Some(node) = doc.json.pointer_mut(&format!("/nodes/{}", t.node)) {
                        set_trs(node, t);
                    }
                }
                if p.corrective.is_some() {
                    // the new target (the last of each mesh) at weight 1
                    for (&m, &(_, total)) in &doc.counts {
                        if let Some(w) = doc
                            .json
                            .pointer_mut(&format!("/meshes/{m}/weights/{}", total - 1))
                        {
                            *w = json!(1.0);
                        }
                    }
                }
            }
            return doc.finish(container);
        }
        if poses.is_empty() {
            return doc.finish(container);
        }
        let n = poses.len();
        let times: Vec<f32> = (0..n).map(|i| i as f32).collect();
        let input = doc.out.push(&mut doc.json, &times, 1, "SCALAR", None);
        doc.json["accessors"][input]["min"] = json!([0.0]);
        doc.json["accessors"][input]["max"] = json!([(n - 1) as f64]);
        let (mut channels, mut samplers) = (Vec::new(), Vec::new());
        for &node in &posed {
            let keys: Vec<NodeTrs> = poses
                .iter()
                .map(|p| {
                    p.nodes
                        .iter()
                        .find(|t| t.node == node)
                        .copied()
                        .or_else(|| rest(node))
                        .unwrap_or(NodeTrs {
                            node,
                            translation: [0.0; 3],
                            rotation: [0.0, 0.0, 0.0, 1.0],
                            scale: [1.0; 3],
                        })
                })
                .collect();
            let mut rotations: Vec<f32> = Vec::with_capacity(4 * n);
            let mut last: Option<[f32; 4]> = None;
            for k in &keys {
                let mut q = k.rotation;
                if let Some(l) = last {
                    if (0..4).map(|c| l[c] * q[c]).sum::<f32>() < 0.0 {
                        q = q.map(|x| -x);
                    }
                }
                rotations.extend(q);
                last = Some(q);
            }
            let translations: Vec<f32> = keys.iter().flat_map(|k| k.translation).collect();
            for (path, values, kind) in [
                ("rotation", rotations, "VEC4"),
                ("translation", translations, "VEC3"),
            ] {
                let output = doc.out.push(
                    &mut doc.json,
                    &values,
                    if kind == "VEC4" { 4 } else { 3 },
                    kind,
                    None,
                );
                channels.push(
                    json!({"sampler": samplers.len(), "target": {"node": node, "path": path}}),
                );
                samplers.push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
            }
        }
        if !targets.is_empty() {
            // pose k's corrective alone at 1 at key k (poses without one: 0)
            let mut slot = Vec::with_capacity(n);
            let mut next = 0;
            for p in poses {
                slot.push(p.corrective.as_ref().map(|_| {
                    next += 1;
                    next - 1
                }));
            }
            let nodes = doc.nodes.clone();
            for (&node, mesh) in &nodes {
                let Some(&(had, total)) = doc.counts.get(mesh) else {
                    continue;
                };
                let mut w = vec![0.0f32; n * total];
                for (k, s) in slot.iter().enumerate() {
                    if let Some(s) = s {
                        w[k * total + had + s] = 1.0;
                    }
                }
                let output = doc.out.push(&mut doc.json, &w, 1, "SCALAR", None);
                channels.push(
                    json!({"sampler": samplers.len(), "target": {"node": node, "path": "weights"}}),
                );
                samplers.push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
            }
        }
        let _ = push(
            &mut doc.json,
            "animations",
            json!({"name": "poses", "channels": channels, "samplers": samplers}),
        );
        doc.finish(container)
    }

    /// Every node's local transform in the file, as TRS.
    fn rest_trs(&self) -> Vec<NodeTrs> {
        let Some(doc) = self.document() else {
            return Vec::new();
        };
        doc.nodes()
            .map(|node| {
                let (translation, rotation, scale) = node.transform().decomposed();
                NodeTrs {
                    node: node.index(),
                    translation,
                    rotation,
                    scale,
                }
            })
            .collect()
    }
}
