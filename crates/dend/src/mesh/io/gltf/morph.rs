//! Poses written as glTF morph targets on the document as read
//! ([`GltfAsset::export_morph_targets`]): what game engines and DCC tools
//! take from a posing tool (a blend shape: the displacement from rest to
//! pose, named, on the untouched asset).

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::{Vector3, Vector4};
use serde_json::{json, Value};

use super::accessor::read_f32;
use super::asset::{Container, GltfAsset};
use super::read::unit;
use super::write::{finish, set_min_max, Shading};
use crate::mesh::Point;

/// One morph target to write: its name and its pose on the asset layout.
#[derive(Debug, Clone)]
pub struct MorphTarget {
    /// The name (in `mesh.extras.targetNames`).
    pub name: String,
    /// The pose, world space, one point per asset vertex (`#A×3`).
    pub pose: Vec<Point>,
    /// The pose's normals (world space, per asset vertex; `None`: no
    /// change), as [`GltfAsset::export`] takes them.
    pub shading: Shading,
}

/// `component_type` FLOAT.
const FLOAT: u32 = 5126;
/// bufferView `target` ARRAY_BUFFER.
const ARRAY_BUFFER: u32 = 34962;

/// The new accessors, bufferViews and bytes of an export, appended after
/// the document's own (whose indices and bytes stay as they are).
pub(super) struct Appender {
    /// Index of the new buffer (after the document's buffers).
    buffer: usize,
    bytes: Vec<u8>,
}

impl Appender {
    /// Appends `values` (`width` floats per element) as a new bufferView
    /// and accessor of type `kind`; returns the accessor's index.
    pub(super) fn push(
        &mut self,
        json: &mut Value,
        values: &[f32],
        width: usize,
        kind: &str,
        target: Option<u32>,
    ) -> usize {
        let offset = self.bytes.len();
        for x in values {
            self.bytes.extend_from_slice(&x.to_le_bytes());
        }
        let mut view = json!({
            "buffer": self.buffer,
            "byteOffset": offset,
            "byteLength": values.len() * 4,
        });
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        let view_index = push(json, "bufferViews", view);
        push(
            json,
            "accessors",
            json!({
                "bufferView": view_index,
                "componentType": FLOAT,
                "count": values.len() / width,
                "type": kind,
            }),
        )
    }
}

/// Appends `item` to the array `key` of object `json` (made an array if
/// it is absent or is not one); returns its index.
pub(super) fn push(json: &mut Value, key: &str, item: Value) -> usize {
    let Some(obj) = json.as_object_mut() else {
        return 0; // a glTF document is an object (checked when read)
    };
    let slot = obj.entry(key).or_insert_with(|| json!([]));
    if !slot.is_array() {
        *slot = json!([]);
    }
    match slot.as_array_mut() {
        Some(arr) => {
            arr.push(item);
            arr.len() - 1
        }
        None => 0,
    }
}

impl GltfAsset {
    /// The document as read plus one morph target per entry of `targets`
    /// on every deformed primitive, as `container`.
    ///
    /// - POSITION deltas are in each primitive's local space (world pose →
    ///   local by the inverse node matrix, minus the stored `f32`
    ///   position; skinned meshes are in mesh space), so node transforms
    ///   and skins apply on top, with exact `min`/`max`.
    /// - NORMAL deltas (posed unit normal, local, minus the stored normal)
    ///   where the primitive has NORMAL.
    /// - Each deformed mesh gets the names in `extras.targetNames` (after
    ///   names of targets it had, invented as `target_<i>` where missing)
    ///   and `weights` of 0 for the new targets.
    /// - `animation`: one more animation, `poses`, keying each deformed
    ///   node's weights linearly from the rest pose (t = 0) through the
    ///   targets in order, target `i` alone at weight 1 at t = `i + 1`
    ///   seconds.
    ///
    /// Everything else, buffers included, is copied byte for byte (the
    /// buffers are merged into one as [`GltfAsset::export`] does; the new
    /// data comes after them).
    pub fn export_morph_targets(
        &self,
        targets: &[MorphTarget],
        animation: bool,
        container: Container,
    ) -> Vec<u8> {
        let mut doc = self.with_morph_targets(targets);
        if animation && !targets.is_empty() {
            animate(
                &mut doc.json,
                &mut doc.out,
                &doc.nodes,
                &doc.counts,
                targets.len(),
            );
        }
        doc.finish(container)
    }

    /// The document with `targets` attached to every deformed primitive
    /// (weights 0), not yet written: what [`Self::export_morph_targets`]
    /// and the skeleton export build on.
    pub(super) fn with_morph_targets(&self, targets: &[MorphTarget]) -> MorphDoc {
        let mut json = self.json.clone();
        let mut out = Appender {
            buffer: self.buffers.len(),
            bytes: Vec::new(),
        };
        // (POSITION accessor of a block) → the new targets' accessors
        let mut made: BTreeMap<usize, Vec<(usize, Option<usize>)>> = BTreeMap::new();
        let mut nodes: BTreeMap<usize, usize> = BTreeMap::new(); // node → mesh
        for b in &self.blocks {
            let Some(mesh) = json
                .pointer(&format!("/nodes/{}/mesh", b.node))
                .and_then(Value::as_u64)
            else {
                continue;
            };
            let _ = nodes.insert(b.node, mesh as usize);
            let stored_normals = b.normal.as_ref().map(|l| read_f32::<3>(l, &self.buffers));
            let lin_t = b.linear().transpose();
            let mut accs = Vec::with_capacity(targets.len());
            for t in targets {
                let mut deltas = Vec::with_capacity(b.local.len());
                for (k, stored) in b.local.iter().enumerate() {
                    let v = b.first + k;
                    let p = t.pose.get(v).copied().unwrap_or(self.positions[v]);
                    let d = if p == self.positions[v] {
                        [0.0f32; 3]
                    } else {
                        let l = b.inverse * Vector4::new(p[0], p[1], p[2], 1.0);
                        let l = [l.x, l.y, l.z];
                        std::array::from_fn(|c| (l[c] - f64::from(stored[c])) as f32)
                    };
                    deltas.push(d);
                }
                let flat: Vec<f32> = deltas.iter().flatten().copied().collect();
                let position = out.push(&mut json, &flat, 3, "VEC3", Some(ARRAY_BUFFER));
                set_min_max(&mut json, position, &deltas);
                let normal = stored_normals.as_ref().map(|stored| {
                    let flat: Vec<f32> = stored
                        .iter()
                        .enumerate()
                        .flat_map(|(k, s)| {
                            let posed = t
                                .shading
                                .normals
                                .get(b.first + k)
                                .copied()
                                .flatten()
                                .and_then(|nw| unit(lin_t * Vector3::from(nw)));
                            let d: [f32; 3] = match posed {
                                Some(u) => std::array::from_fn(|c| (u[c] - f64::from(s[c])) as f32),
                                None => [0.0; 3],
                            };
                            d
                        })
                        .collect();
                    out.push(&mut json, &flat, 3, "VEC3", Some(ARRAY_BUFFER))
                });
                accs.push((position, normal));
            }
            let _ = made.insert(b.position.accessor, accs);
        }
        let meshes: BTreeSet<usize> = nodes.values().copied().collect();
        let mut target_counts = BTreeMap::new(); // mesh → (had, total)
        for &m in &meshes {
            let had = attach(&mut json, m, &made, targets);
            let _ = target_counts.insert(m, (had, had + targets.len()));
        }
        let mut buffers = self.buffers.clone();
        buffers.push(Vec::new());
        MorphDoc {
            json,
            out,
            buffers,
            nodes,
            counts: target_counts,
        }
    }
}

/// A document being exported: the JSON, the data appended so far, and
/// for each deformed node its mesh, for each mesh its target counts
/// before and after the new targets.
pub(super) struct MorphDoc {
    pub json: Value,
    pub out: Appender,
    /// The document's buffers, and an empty last one the appended data
    /// goes into.
    buffers: Vec<Vec<u8>>,
    pub nodes: BTreeMap<usize, usize>,
    pub counts: BTreeMap<usize, (usize, usize)>,
}

impl MorphDoc {
    /// Writes the document as `container`.
    pub fn finish(mut self, container: Container) -> Vec<u8> {
        if let Some(last) = self.buffers.last_mut() {
            *last = std::mem::take(&mut self.out.bytes);
        }
        finish(self.json, &self.buffers, container)
    }
}

/// Adds the targets made for mesh `m`'s primitives (by their POSITION
/// accessor), its `extras.targetNames` and its `weights`; returns how many
/// targets the mesh had before.
fn attach(
    json: &mut Value,
    m: usize,
    made: &BTreeMap<usize, Vec<(usize, Option<usize>)>>,
    targets: &[MorphTarget],
) -> usize {
    let Some(mesh) = json.pointer_mut(&format!("/meshes/{m}")) else {
        return 0;
    };
    let mut had = 0;
    if let Some(prims) = mesh.get_mut("primitives").and_then(Value::as_array_mut) {
        for prim in prims {
            let pos = prim
                .pointer("/attributes/POSITION")
                .and_then(Value::as_u64)
                .map(|a| a as usize);
            let has_normal = prim.pointer("/attributes/NORMAL").is_some();
            let Some(accs) = pos.and_then(|p| made.get(&p)) else {
                continue;
            };
            had = had.max(
                prim.get("targets")
                    .and_then(Value::as_array)
                    .map_or(0, Vec::len),
            );
            for (position, normal) in accs {
                let mut t = json!({"POSITION": position});
                if let (Some(n), true) = (normal, has_normal) {
                    t["NORMAL"] = json!(n);
                }
                let _ = push(prim, "targets", t);
            }
        }
    }
    let mut weights: Vec<Value> = mesh
        .get("weights")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    weights.resize(had, json!(0.0));
    weights.extend(targets.iter().map(|_| json!(0.0)));
    mesh["weights"] = Value::Array(weights);
    if mesh.get("extras").is_none() {
        mesh["extras"] = json!({});
    }
    if let Some(extras) = mesh.get_mut("extras").and_then(Value::as_object_mut) {
        let mut names: Vec<Value> = extras
            .get("targetNames")
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default();
        names.truncate(had);
        while names.len() < had {
            names.push(json!(format!("target_{}", names.len())));
        }
        names.extend(targets.iter().map(|t| json!(t.name)));
        let _ = extras.insert("targetNames".into(), Value::Array(names));
    }
    had
}

/// Appends the `poses` animation: per deformed node, its weights keyed
/// from rest (t = 0) through the `n` new targets (target `i` alone at 1 at
/// t = `i + 1`); targets the mesh had before keep weight 0.
fn animate(
    json: &mut Value,
    out: &mut Appender,
    nodes: &BTreeMap<usize, usize>,
    counts: &BTreeMap<usize, (usize, usize)>,
    n: usize,
) {
    let times: Vec<f32> = (0..=n).map(|i| i as f32).collect();
    let input = out.push(json, &times, 1, "SCALAR", None);
    json["accessors"][input]["min"] = json!([0.0]);
    json["accessors"][input]["max"] = json!([n as f64]);
    let mut outputs: BTreeMap<(usize, usize), usize> = BTreeMap::new();
    let (mut channels, mut samplers) = (vec![], vec![]);
    for (&node, mesh) in nodes {
        let Some(&(had, total)) = counts.get(mesh) else {
            continue;
        };
        let output = *outputs.entry((had, total)).or_insert_with(|| {
            let mut w = vec![0.0f32; (n + 1) * total];
            for i in 0..n {
                w[(i + 1) * total + had + i] = 1.0;
            }
            out.push(json, &w, 1, "SCALAR", None)
        });
        channels
            .push(json!({"sampler": samplers.len(), "target": {"node": node, "path": "weights"}}));
        samplers.push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
    }
    let _ = push(
        json,
        "animations",
        json!({"name": "poses", "channels": channels, "samplers": samplers}),
    );
}
