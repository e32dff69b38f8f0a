//! A generated game-style glTF asset for tests and examples: a UV-mapped,
//! optionally skinned tube with caps, built the way exporters build them.
//!
//! - primitive 0, the tube: `rings` rings of `around` vertices plus a
//!   duplicated **UV seam column** (u = 0 and u = 1 at the same positions,
//!   same normals); smooth NORMAL, TANGENT, TEXCOORD_0; POSITION and NORMAL
//!   interleaved in one bufferView (stride 24); `u16` indices;
//! - primitive 1, the two caps: flat discs whose rim vertices repeat the
//!   tube's end rings with the cap's normal (**hard edges**), their own UVs;
//!   `u8` indices; another material;
//! - skinned: JOINTS_0 (`u16`) and WEIGHTS_0 blending two joints along the
//!   tube, a skin with inverse bind matrices, the mesh node untransformed;
//!   unskinned: the mesh node under a translated parent, rotated and scaled
//!   non-uniformly.
//!
//! The tube is `radius 0.5`, `z ∈ [0, 3]`. Welded it is a closed surface of
//! `around × rings + 2` vertices; the file has `(around + 1) × (rings + 2)`.

use serde_json::{json, Value};

use crate::mesh::io::gltf::{Container, GltfError};

/// Options of [`tube`].
#[derive(Debug, Clone, Copy)]
pub struct TubeOptions {
    /// Vertices around (≥ 3).
    pub around: usize,
    /// Rings along z (≥ 2).
    pub rings: usize,
    /// Skinned (two joints) or placed by a transformed node hierarchy.
    pub skinned: bool,
    /// GLB or `.gltf` with a data-URI buffer.
    pub container: Container,
}

impl Default for TubeOptions {
    fn default() -> Self {
        TubeOptions {
            around: 16,
            rings: 13,
            skinned: true,
            container: Container::Glb,
        }
    }
}

struct Buf(Vec<u8>);

impl Buf {
    fn f32s(&mut self, xs: impl IntoIterator<Item = f32>) {
        xs.into_iter()
            .for_each(|x| self.0.extend_from_slice(&x.to_le_bytes()));
    }
    fn align(&mut self) {
        self.0.resize(self.0.len().next_multiple_of(4), 0);
    }
    /// The bufferView of what was written since `start` (vertex data).
    fn vertex_view(&self, start: usize) -> Value {
        json!({"buffer": 0, "byteOffset": start, "byteLength": self.0.len() - start, "target": 34962})
    }
}

/// The asset's bytes (see the module documentation).
pub fn tube(o: TubeOptions) -> Result<Vec<u8>, GltfError> {
    let (n, r) = (o.around, o.rings);
    if n < 3 || r < 2 || (n + 1) * r > u16::MAX as usize || n + 2 > 255 {
        return Err(GltfError::Invalid {
            message: format!(
                "tube of {n} × {r} is outside 3..=253 around, 2.. rings (u16 indices)"
            ),
        });
    }
    let mut b = Buf(Vec::new());
    let g = Geometry::write(&mut b, n, r);
    let mut views = g.views.clone();
    let mut accessors = g.accessors(n, r);
    let mut tube_attr = json!({"POSITION": 0, "NORMAL": 1, "TANGENT": 2, "TEXCOORD_0": 3});
    let mut cap_attr = json!({"POSITION": 4, "NORMAL": 5, "TEXCOORD_0": 6});
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "dend sample tube"},
        "scene": 0,
        "materials": [
            {"name": "side", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.3, 0.2, 1.0]}},
            {"name": "cap", "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.3, 0.8, 1.0]}}
        ],
    });
    if o.skinned {
        let base = accessors.len();
        accessors.extend(g.skin(&mut b, &mut views, n, r));
        tube_attr["JOINTS_0"] = json!(base);
        tube_attr["WEIGHTS_0"] = json!(base + 2);
        cap_attr["JOINTS_0"] = json!(base + 1);
        cap_attr["WEIGHTS_0"] = json!(base + 3);
        doc["skins"] = json!([{"joints": [1, 2], "inverseBindMatrices": base + 4, "skeleton": 1}]);
        doc["nodes"] = json!([
            {"name": "tube", "mesh": 0, "skin": 0},
            {"name": "hip", "children": [2]},
            {"name": "tip", "translation": [0.0, 0.0, 1.5]}
        ]);
        doc["scenes"] = json!([{"name": "skinned tube", "nodes": [0, 1]}]);
    } else {
        doc["nodes"] = json!([
            {"name": "parent", "translation": [1.0, 2.0, 3.0], "children": [1]},
            {"name": "tube", "mesh": 0, "rotation": [0.5, 0.5, 0.5, 0.5], "scale": [1.0, 2.0, 0.5]}
        ]);
        doc["scenes"] = json!([{"nodes": [0]}]);
    }
    doc["meshes"] = json!([{"name": "tube", "primitives": [
        {"attributes": tube_attr, "indices": 7, "material": 0, "mode": 4},
        {"attributes": cap_attr, "indices": 8, "material": 1}
    ]}]);
    doc["accessors"] = json!(accessors);
    doc["bufferViews"] = json!(views);
    doc["buffers"] = json!([{"byteLength": b.0.len()}]);
    let text = serde_json::to_vec(&doc).unwrap_or_default();
    Ok(crate::mesh::io::gltf::assemble(&text, b.0, o.container))
}

/// The two primitives' vertices and indices, written to the buffer as
/// bufferViews 0 to 7.
struct Geometry {
    tube_pos: Vec<[f32; 3]>,
    cap_pos: Vec<[f32; 3]>,
    views: Vec<Value>,
    tube_idx: usize,
    cap_idx: usize,
}

impl Geometry {
    /// Writes views 0 to 7: the tube's POSITION + NORMAL (interleaved),
    /// TANGENT and TEXCOORD_0; the caps' POSITION, NORMAL and TEXCOORD_0;
    /// the tube's `u16` and the caps' `u8` indices.
    fn write(b: &mut Buf, n: usize, r: usize) -> Geometry {
        let ring = |c: usize| {
            let a = std::f64::consts::TAU * (c % n) as f64 / n as f64;
            (a.cos(), a.sin())
        };
        let z_of = |k: usize| (3.0 * k as f64 / (r - 1) as f64) as f32;
        let mut views = Vec::new();
        // view 0: tube POSITION + NORMAL interleaved
        let mut tube_pos = Vec::new();
        for k in 0..r {
            for c in 0..=n {
                let (x, y) = ring(c);
                let p = [(0.5 * x) as f32, (0.5 * y) as f32, z_of(k)];
                tube_pos.push(p);
                b.f32s(p);
                b.f32s([x as f32, y as f32, 0.0]);
            }
        }
        views.push(json!({"buffer": 0, "byteOffset": 0, "byteLength": b.0.len(), "byteStride": 24, "target": 34962}));
        // view 1: tube TANGENT, view 2: tube TEXCOORD_0
        let t0 = b.0.len();
        for _ in 0..r {
            for c in 0..=n {
                let (x, y) = ring(c);
                b.f32s([-y as f32, x as f32, 0.0, 1.0]);
            }
        }
        views.push(b.vertex_view(t0));
        let u0 = b.0.len();
        for k in 0..r {
            for c in 0..=n {
                b.f32s([c as f32 / n as f32, k as f32 / (r - 1) as f32]);
            }
        }
        views.push(b.vertex_view(u0));
        // view 3: caps POSITION, 4: NORMAL, 5: TEXCOORD_0
        let mut cap_pos = Vec::new();
        for (k, z) in [(0, 0.0f32), (r - 1, z_of(r - 1))] {
            cap_pos.push([0.0, 0.0, z]);
            for c in 0..n {
                cap_pos.push(tube_pos[k * (n + 1) + c]);
            }
        }
        let p0 = b.0.len();
        cap_pos.iter().for_each(|p| b.f32s(*p));
        views.push(b.vertex_view(p0));
        let n0 = b.0.len();
        for side in [-1.0f32, 1.0] {
            for _ in 0..=n {
                b.f32s([0.0, 0.0, side]);
            }
        }
        views.push(b.vertex_view(n0));
        let c0 = b.0.len();
        for _ in 0..2 {
            b.f32s([0.5, 0.5]);
            for c in 0..n {
                let (x, y) = ring(c);
                b.f32s([(0.5 + 0.5 * x) as f32, (0.5 + 0.5 * y) as f32]);
            }
        }
        views.push(b.vertex_view(c0));
        let (tube_idx, cap_idx) = Self::write_indices(b, &mut views, n, r);
        Geometry {
            tube_pos,
            cap_pos,
            views,
            tube_idx,
            cap_idx,
        }
    }

    /// Views 6 (tube indices, `u16`) and 7 (cap indices, `u8`); their counts.
    fn write_indices(b: &mut Buf, views: &mut Vec<Value>, n: usize, r: usize) -> (usize, usize) {
        let i0 = b.0.len();
        let mut tube_idx = 0;
        for k in 0..r - 1 {
            for c in 0..n {
                let v = |k: usize, c: usize| (k * (n + 1) + c) as u16;
                let quad = [v(k, c), v(k, c + 1), v(k + 1, c + 1), v(k + 1, c)];
                for t in [[0, 1, 2], [0, 2, 3]] {
                    t.iter()
                        .for_each(|&i| b.0.extend_from_slice(&quad[i].to_le_bytes()));
                    tube_idx += 3;
                }
            }
        }
        views.push(
            json!({"buffer": 0, "byteOffset": i0, "byteLength": b.0.len() - i0, "target": 34963}),
        );
        b.align();
        let i1 = b.0.len();
        let mut cap_idx = 0;
        for c in 0..n {
            let (a, d) = (1 + c as u8, 1 + ((c + 1) % n) as u8);
            b.0.extend_from_slice(&[0, d, a]); // bottom, facing -z
            let top = (n + 1) as u8;
            b.0.extend_from_slice(&[top, top + a, top + d]); // top, facing +z
            cap_idx += 6;
        }
        views.push(
            json!({"buffer": 0, "byteOffset": i1, "byteLength": b.0.len() - i1, "target": 34963}),
        );
        b.align();
        (tube_idx, cap_idx)
    }

    /// Accessors 0 to 8 of views 0 to 7 (positions with their bounds).
    fn accessors(&self, n: usize, r: usize) -> Vec<Value> {
        let (nt, nc) = (r * (n + 1), 2 * (n + 1));
        let bounds = |ps: &[[f32; 3]]| {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for p in ps {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            (lo, hi)
        };
        let (tlo, thi) = bounds(&self.tube_pos);
        let (clo, chi) = bounds(&self.cap_pos);
        vec![
            json!({"bufferView": 0, "componentType": 5126, "count": nt, "type": "VEC3", "min": tlo, "max": thi}),
            json!({"bufferView": 0, "byteOffset": 12, "componentType": 5126, "count": nt, "type": "VEC3"}),
            json!({"bufferView": 1, "componentType": 5126, "count": nt, "type": "VEC4"}),
            json!({"bufferView": 2, "componentType": 5126, "count": nt, "type": "VEC2"}),
            json!({"bufferView": 3, "componentType": 5126, "count": nc, "type": "VEC3", "min": clo, "max": chi}),
            json!({"bufferView": 4, "componentType": 5126, "count": nc, "type": "VEC3"}),
            json!({"bufferView": 5, "componentType": 5126, "count": nc, "type": "VEC2"}),
            json!({"bufferView": 6, "componentType": 5123, "count": self.tube_idx, "type": "SCALAR"}),
            json!({"bufferView": 7, "componentType": 5121, "count": self.cap_idx, "type": "SCALAR"}),
        ]
    }

    /// The skin's views (8: JOINTS_0 of tube and caps, `u16` ×4, then
    /// WEIGHTS_0, then the inverse binds) and its five accessors: tube
    /// joints, cap joints, tube weights, cap weights, inverse binds.
    fn skin(&self, b: &mut Buf, views: &mut Vec<Value>, n: usize, r: usize) -> Vec<Value> {
        let (nt, nc) = (r * (n + 1), 2 * (n + 1));
        let mut joints = |ps: &[[f32; 3]], b: &mut Buf| {
            let s = b.0.len();
            for p in ps {
                // joint 1 has weight z/3: not named where that is 0
                let j1 = u16::from(p[2] > 0.0);
                for j in [0u16, j1, 0, 0] {
                    b.0.extend_from_slice(&j.to_le_bytes());
                }
            }
            views.push(b.vertex_view(s));
            views.len() - 1
        };
        let jt = joints(&self.tube_pos, b);
        let jc = joints(&self.cap_pos, b);
        let mut weights = |ps: &[[f32; 3]], b: &mut Buf| {
            let s = b.0.len();
            for p in ps {
                let t = p[2] / 3.0;
                b.f32s([1.0 - t, t, 0.0, 0.0]);
            }
            views.push(b.vertex_view(s));
            views.len() - 1
        };
        let wt = weights(&self.tube_pos, b);
        let wc = weights(&self.cap_pos, b);
        let s = b.0.len();
        let id = [1.0f32, 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.];
        b.f32s(id.iter().copied().chain([0.0, 0.0, 0.0, 1.0]));
        b.f32s(id.iter().copied().chain([0.0, 0.0, -1.5, 1.0]));
        views.push(json!({"buffer": 0, "byteOffset": s, "byteLength": 128}));
        let ibm = views.len() - 1;
        vec![
            json!({"bufferView": jt, "componentType": 5123, "count": nt, "type": "VEC4"}),
            json!({"bufferView": jc, "componentType": 5123, "count": nc, "type": "VEC4"}),
            json!({"bufferView": wt, "componentType": 5126, "count": nt, "type": "VEC4"}),
            json!({"bufferView": wc, "componentType": 5126, "count": nc, "type": "VEC4"}),
            json!({"bufferView": ibm, "componentType": 5126, "count": 2, "type": "MAT4"}),
        ]
    }
}
