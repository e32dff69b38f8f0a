//! A generated rigged limb for tests and examples: a capped tube along +y
//! skinned to a chain of joints, built the way DCC exporters write one.
//!
//! - nodes: `Armature` (no mesh, not a joint, translated by
//!   [`LimbOptions::offset`]) → `bone0` → `bone1` → … → `bone{n-1}` → `end`
//!   (a leaf joint no vertex is weighted to, as exporters add for the last
//!   bone's tail), each bone [`LimbOptions::bone`] long along +y; the mesh
//!   node `limb` at the root, untransformed, with skin 0 over the joints;
//! - the tube: radius `0.3 · bone`, `rings_per_bone` rings per bone of
//!   `around` vertices, a pole vertex closing each end (a closed surface);
//! - weights: vertex at height `y` (from the chain's root) belongs to bone
//!   `k = ⌊y / bone⌋`, blended with the neighbouring bone over
//!   `blend · bone` either side of each inner joint by a smoothstep, so at
//!   most two joints influence a vertex and the weights sum to one;
//! - the bind pose is the rest pose (`IBM_j = G_j⁻¹`).
//!
//! [`limb_constraints`] is its default edit (the `limb` of
//! `POST /v1/meshes/generate`): the first bone's region fixed, the last
//! bone's (with the `end` joint's) a handle named after it that turns
//! about its head.

use serde_json::json;

use super::error::RigError;
use crate::mesh::asset::groups::NameOrIndex;
use crate::mesh::asset::Asset;
use crate::mesh::io::gltf::{assemble, Container};
use crate::mesh::selection::{ConstraintsSpec, HandleSpec, JointSel, VertexSet};

/// Options of [`limb`].
#[derive(Debug, Clone, Copy)]
pub struct LimbOptions {
    /// Bones in the chain (weighted joints, ≥ 1); the skin has one more
    /// joint, the unweighted `end`.
    pub bones: usize,
    /// Bone length.
    pub bone: f32,
    /// Rings per bone (≥ 2).
    pub rings_per_bone: usize,
    /// Vertices around (≥ 3).
    pub around: usize,
    /// Half-width of the weight blend at each inner joint, as a fraction of
    /// a bone (0: rigid skinning, at most 0.5).
    pub blend: f32,
    /// Translation of the `Armature` node.
    pub offset: [f32; 3],
    /// GLB or `.gltf`.
    pub container: Container,
}

impl Default for LimbOptions {
    fn default() -> Self {
        LimbOptions {
            bones: 3,
            bone: 1.0,
            rings_per_bone: 8,
            around: 12,
            blend: 0.25,
            offset: [0.0, 0.0, 0.0],
            container: Container::Glb,
        }
    }
}

/// The smoothstep `3t² − 2t³` of `t` clamped to `[0, 1]`.
fn smoothstep(t: f32) -> f32 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The weights of a vertex at height `y` (chain coordinates): up to two
/// `(joint, weight)` pairs.
fn weights(o: &LimbOptions, y: f32) -> [(u16, f32); 2] {
    let n = o.bones;
    let k = ((y / o.bone).floor().max(0.0) as usize).min(n - 1);
    let half = o.blend * o.bone;
    // the inner joint nearest y and how far past it
    let below = k as f32 * o.bone;
    let above = (k + 1) as f32 * o.bone;
    if half > 0.0 && k > 0 && y - below < half {
        let t = smoothstep((y - below + half) / (2.0 * half));
        return [(k as u16 - 1, 1.0 - t), (k as u16, t)];
    }
    if half > 0.0 && k + 1 < n && above - y < half {
        let t = smoothstep((y - above + half) / (2.0 * half));
        return [(k as u16, 1.0 - t), (k as u16 + 1, t)];
    }
    [(k as u16, 1.0), (k as u16, 0.0)]
}

/// The limb's bytes (see the module documentation).
pub fn limb(o: LimbOptions) -> Vec<u8> {
    let o = LimbOptions {
        bones: o.bones.max(1),
        rings_per_bone: o.rings_per_bone.max(2),
        around: o.around.max(3),
        blend: o.blend.clamp(0.0, 0.5),
        ..o
    };
    let (n, r) = (o.around, o.bones * o.rings_per_bone + 1);
    let length = o.bones as f32 * o.bone;
    let radius = 0.3 * o.bone;
    let mut pos: Vec<[f32; 3]> = Vec::new();
    let mut nor: Vec<[f32; 3]> = Vec::new();
    let mut chain_y: Vec<f32> = Vec::new();
    for k in 0..r {
        let y = length * k as f32 / (r - 1) as f32;
        for c in 0..n {
            let a = std::f32::consts::TAU * c as f32 / n as f32;
            pos.push([radius * a.cos(), y, radius * a.sin()]);
            chain_y.push(y);
            nor.push([a.cos(), 0.0, a.sin()]);
        }
    }
    let (bottom, top) = (pos.len() as u32, pos.len() as u32 + 1);
    pos.push([0.0, -radius, 0.0]);
    nor.push([0.0, -1.0, 0.0]);
    chain_y.push(-radius);
    pos.push([0.0, length + radius, 0.0]);
    nor.push([0.0, 1.0, 0.0]);
    chain_y.push(length + radius);
    // the armature's offset places the limb
    pos.iter_mut()
        .for_each(|p| *p = std::array::from_fn(|k| p[k] + o.offset[k]));
    let mut idx: Vec<u32> = Vec::new();
    let at = |k: usize, c: usize| (k * n + c % n) as u32;
    for k in 0..r - 1 {
        for c in 0..n {
            // counter-clockwise seen from outside
            idx.extend([at(k, c), at(k + 1, c), at(k + 1, c + 1)]);
            idx.extend([at(k, c), at(k + 1, c + 1), at(k, c + 1)]);
        }
    }
    for c in 0..n {
        idx.extend([bottom, at(0, c), at(0, c + 1)]);
        idx.extend([top, at(r - 1, c + 1), at(r - 1, c)]);
    }
    let mut bin: Vec<u8> = Vec::new();
    let f32s = |bin: &mut Vec<u8>, xs: &[f32]| {
        xs.iter()
            .for_each(|x| bin.extend_from_slice(&x.to_le_bytes()))
    };
    let mut views = Vec::new();
    let mut view = |bin: &Vec<u8>, start: usize, target: Option<u32>| {
        let mut v = json!({"buffer": 0, "byteOffset": start, "byteLength": bin.len() - start});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        views.push(v);
        views.len() - 1
    };
    let s = bin.len();
    pos.iter().for_each(|p| f32s(&mut bin, p));
    let v_pos = view(&bin, s, Some(34962));
    let s = bin.len();
    nor.iter().for_each(|p| f32s(&mut bin, p));
    let v_nor = view(&bin, s, Some(34962));
    let s = bin.len();
    for &y in &chain_y {
        for (j, _) in weights(&o, y) {
            bin.extend_from_slice(&j.to_le_bytes());
        }
        bin.extend_from_slice(&[0; 4]);
    }
    let v_joints = view(&bin, s, Some(34962));
    let s = bin.len();
    for &y in &chain_y {
        let w = weights(&o, y);
        f32s(&mut bin, &[w[0].1, w[1].1, 0.0, 0.0]);
    }
    let v_weights = view(&bin, s, Some(34962));
    let s = bin.len();
    idx.iter()
        .for_each(|i| bin.extend_from_slice(&i.to_le_bytes()));
    let v_idx = view(&bin, s, Some(34963));
    // inverse bind matrices: the joints' rest globals are translations
    let s = bin.len();
    let joints = o.bones + 1;
    for j in 0..joints {
        let y = o.offset[1] + j as f32 * o.bone;
        f32s(
            &mut bin,
            &[
                1.0,
                0.0,
                0.0,
                0.0,
                0.0,
                1.0,
                0.0,
                0.0,
                0.0,
                0.0,
                1.0,
                0.0,
                -o.offset[0],
                -y,
                -o.offset[2],
                1.0,
            ],
        );
    }
    let v_ibm = view(&bin, s, None);
    let (lo, hi) = pos.iter().fold(
        ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
        |(lo, hi), p| {
            (
                std::array::from_fn(|k| lo[k].min(p[k])),
                std::array::from_fn(|k| hi[k].max(p[k])),
            )
        },
    );
    let count = pos.len();
    // nodes: 0 the mesh, 1 the armature, 2.. the bones, then the end
    let mut nodes = vec![
        json!({"name": "limb", "mesh": 0, "skin": 0}),
        json!({"name": "Armature", "translation": o.offset, "children": [2]}),
    ];
    for j in 0..joints {
        let name = if j == o.bones {
            "end".to_owned()
        } else {
            format!("bone{j}")
        };
        let mut node = json!({"name": name});
        if j > 0 {
            node["translation"] = json!([0.0, o.bone, 0.0]);
        }
        if j + 1 < joints {
            node["children"] = json!([j + 3]);
        }
        nodes.push(node);
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "dend sample limb"},
        "scene": 0,
        "scenes": [{"name": "limb", "nodes": [0, 1]}],
        "nodes": nodes,
        "skins": [{"joints": (2..2 + joints).collect::<Vec<_>>(), "inverseBindMatrices": 5, "skeleton": 1}],
        "meshes": [{"name": "limb", "primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "JOINTS_0": 2, "WEIGHTS_0": 3},
            "indices": 4, "mode": 4
        }]}],
        "accessors": [
            {"bufferView": v_pos, "componentType": 5126, "count": count, "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": v_nor, "componentType": 5126, "count": count, "type": "VEC3"},
            {"bufferView": v_joints, "componentType": 5123, "count": count, "type": "VEC4"},
            {"bufferView": v_weights, "componentType": 5126, "count": count, "type": "VEC4"},
            {"bufferView": v_idx, "componentType": 5125, "count": idx.len(), "type": "SCALAR"},
            {"bufferView": v_ibm, "componentType": 5126, "count": joints, "type": "MAT4"}
        ],
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    let text = serde_json::to_vec(&doc).unwrap_or_default();
    assemble(&text, bin, o.container)
}

/// The limb's default edit as index lists (ready for `PUT …/constraints`):
/// `bone0`'s region fixed, and the last bone with its children a handle
/// named after it, its pivot the bone's head (a drag's rotation bends the
/// limb at that joint). [`RigError`] when `asset` has no usable skin.
pub fn limb_constraints(asset: &Asset) -> Result<ConstraintsSpec, RigError> {
    let sk = asset.skeleton()?;
    let joints = sk.joints();
    // the last joint with vertices of its own (the limb's `end` has none)
    let last = (0..joints.len())
        .rev()
        .find(|&k| {
            sk.joint_vertices(&JointSel {
                joint: NameOrIndex::Index(k),
                with_children: false,
            })
            .is_ok_and(|v| !v.is_empty())
        })
        .unwrap_or(0);
    let indices = |k: usize, with_children: bool| -> Result<VertexSet, RigError> {
        let v = sk.joint_vertices(&JointSel {
            joint: NameOrIndex::Index(k),
            with_children,
        })?;
        Ok(VertexSet::Indices(v.into_iter().map(u64::from).collect()))
    };
    let head = joints[last].head;
    Ok(ConstraintsSpec {
        fixed: indices(0, false)?,
        fixed_positions: None,
        handles: vec![HandleSpec {
            name: Some(joints[last].name.clone()),
            vertices: indices(last, true)?,
            translate: None,
            rotate: None,
            pivot: Some([head.x, head.y, head.z]),
            positions: None,
        }],
    })
}
