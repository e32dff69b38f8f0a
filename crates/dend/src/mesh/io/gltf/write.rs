//! Writing glTF: a pose put back into the asset it was read from
//! ([`GltfAsset::export`]), and a plain mesh as a minimal document
//! ([`write_mesh`]).
//!
//! The document is edited as JSON (`serde_json::Value`), not re-serialised
//! from `gltf-json`'s typed `Root`: the typed form drops fields and
//! extensions it does not model, and export must change only what the pose
//! changes.

use nalgebra::{Vector3, Vector4};
use serde_json::{json, Value};

use super::accessor::write_f32;
use super::asset::{Container, GltfAsset};
use super::container::{assemble_glb, data_uri};
use super::read::unit;
use crate::mesh::{cross, sub, Point};

/// Per asset vertex, what export writes besides positions: `None` keeps the
/// file's value.
#[derive(Debug, Clone, Default)]
pub struct Shading {
    /// World-space unit normals.
    pub normals: Vec<Option<Point>>,
    /// World-space unit tangent directions (the file's `w` sign is kept).
    pub tangents: Vec<Option<Point>>,
}

impl GltfAsset {
    /// The document with `pose` (world space, one point per asset vertex)
    /// written into the POSITION accessors (and `shading` into NORMAL and
    /// TANGENT), as `container`.
    ///
    /// What changes: the POSITION, NORMAL and TANGENT bytes of the deformed
    /// primitives, in place (same accessors, offsets and strides), the
    /// POSITION accessors' `min`/`max`, and the buffers, which are merged into
    /// one (the GLB BIN chunk, or one base64 data URI for `.gltf`) with every
    /// bufferView's offset moved accordingly. Everything else (indices, UVs,
    /// colours, joints, weights, morph targets, materials, images, animations,
    /// extensions, extras) is copied byte for byte. A vertex whose pose equals
    /// its rest position keeps its stored `f32` bits exactly.
    pub fn export(&self, pose: &[Point], shading: &Shading, container: Container) -> Vec<u8> {
        let mut buffers = self.buffers.clone();
        let mut json = self.json.clone();
        for b in &self.blocks {
            let n = b.position.count;
            let range = b.first..b.first + n;
            let local: Vec<[f32; 3]> = range
                .clone()
                .zip(&b.local)
                .map(|(v, stored)| {
                    let p = pose.get(v).copied().unwrap_or(self.positions[v]);
                    if p == self.positions[v] {
                        *stored
                    } else {
                        let l = b.inverse * Vector4::new(p[0], p[1], p[2], 1.0);
                        [l.x as f32, l.y as f32, l.z as f32]
                    }
                })
                .collect();
            write_f32(&b.position, &mut buffers, &local);
            set_min_max(&mut json, b.position.accessor, &local);
            let lin = b.linear();
            if let Some(loc) = &b.normal {
                let mut stored = super::accessor::read_f32::<3>(loc, &buffers);
                for (k, v) in range.clone().enumerate() {
                    if let Some(Some(nw)) = shading.normals.get(v) {
                        let l = lin.transpose() * Vector3::from(*nw);
                        if let Some(u) = unit(l) {
                            stored[k] = u.map(|x| x as f32);
                        }
                    }
                }
                write_f32(loc, &mut buffers, &stored);
            }
            if let Some(loc) = &b.tangent {
                let inv = b.inverse.fixed_view::<3, 3>(0, 0).into_owned();
                let mut stored = super::accessor::read_f32::<4>(loc, &buffers);
                for (k, v) in range.clone().enumerate() {
                    if let Some(Some(tw)) = shading.tangents.get(v) {
                        if let Some(u) = unit(inv * Vector3::from(*tw)) {
                            stored[k] = [u[0] as f32, u[1] as f32, u[2] as f32, stored[k][3]];
                        }
                    }
                }
                write_f32(loc, &mut buffers, &stored);
            }
        }
        finish(json, &buffers, container)
    }
}

/// Sets accessor `index`'s `min`/`max` to the bounds of `values`.
pub(super) fn set_min_max(json: &mut Value, index: usize, values: &[[f32; 3]]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for v in values {
        for k in 0..3 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    if values.is_empty() {
        return;
    }
    if let Some(acc) = json.pointer_mut(&format!("/accessors/{index}")) {
        acc["min"] = json!(lo.map(f64::from));
        acc["max"] = json!(hi.map(f64::from));
    }
}

/// Merges `buffers` into one (each part at a 4-byte aligned offset), moves
/// the bufferViews onto it and writes the container.
pub(super) fn finish(mut json: Value, buffers: &[Vec<u8>], container: Container) -> Vec<u8> {
    let mut merged = Vec::new();
    let mut base = Vec::with_capacity(buffers.len());
    for b in buffers {
        base.push(merged.len());
        merged.extend_from_slice(b);
        merged.resize(merged.len().next_multiple_of(4), 0);
    }
    if let Some(views) = json.get_mut("bufferViews").and_then(Value::as_array_mut) {
        for v in views {
            let buffer = v.get("buffer").and_then(Value::as_u64).unwrap_or(0) as usize;
            let off = v.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
            v["buffer"] = json!(0);
            v["byteOffset"] = json!(off + base.get(buffer).copied().unwrap_or(0));
        }
    }
    if !merged.is_empty() {
        let mut first = json
            .get("buffers")
            .and_then(|b| b.get(0))
            .cloned()
            .unwrap_or_else(|| json!({}));
        first["byteLength"] = json!(merged.len());
        match container {
            Container::Glb => {
                if let Some(o) = first.as_object_mut() {
                    o.remove("uri");
                }
            }
            Container::Json => first["uri"] = json!(data_uri(&merged)),
        }
        json["buffers"] = json!([first]);
    }
    let text = serde_json::to_vec(&json).unwrap_or_default();
    match container {
        Container::Glb => assemble_glb(&text, &merged),
        Container::Json => text,
    }
}

/// A plain mesh as a minimal glTF document: one node, one mesh, one
/// TRIANGLES primitive with `f32` POSITION (with `min`/`max`), area-weighted
/// smooth NORMAL and `u32` indices.
pub fn write_mesh(positions: &[Point], triangles: &[[u32; 3]], container: Container) -> Vec<u8> {
    let mut normals = vec![[0.0f64; 3]; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions.get(i as usize).copied().unwrap_or_default());
        let n = cross(sub(b, a), sub(c, a));
        for &i in t {
            if let Some(s) = normals.get_mut(i as usize) {
                *s = [s[0] + n[0], s[1] + n[1], s[2] + n[2]];
            }
        }
    }
    let mut bin = Vec::with_capacity(positions.len() * 24 + triangles.len() * 12);
    let local: Vec<[f32; 3]> = positions.iter().map(|p| p.map(|x| x as f32)).collect();
    for p in &local {
        p.iter()
            .for_each(|x| bin.extend_from_slice(&x.to_le_bytes()));
    }
    let normals_at = bin.len();
    for n in &normals {
        let u = unit(Vector3::from(*n)).unwrap_or([0.0, 0.0, 1.0]);
        u.iter()
            .for_each(|x| bin.extend_from_slice(&(*x as f32).to_le_bytes()));
    }
    let indices_at = bin.len();
    for t in triangles {
        t.iter()
            .for_each(|i| bin.extend_from_slice(&i.to_le_bytes()));
    }
    let n = positions.len();
    let doc = json!({
        "asset": {"version": "2.0", "generator": concat!("dend ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "mode": 4}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": normals_at, "target": 34962},
            {"buffer": 0, "byteOffset": normals_at, "byteLength": indices_at - normals_at, "target": 34962},
            {"buffer": 0, "byteOffset": indices_at, "byteLength": bin.len() - indices_at, "target": 34963}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": n, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5125, "count": triangles.len() * 3, "type": "SCALAR"}
        ]
    });
    let mut doc = doc;
    set_min_max(&mut doc, 0, &local);
    finish(doc, &[bin], container)
}
