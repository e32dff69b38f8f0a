//! Normals of a deformed asset are recomputed (angle-weighted, per normal
//! group, hard edges kept) and tangents re-orthogonalised: checked against a
//! brute-force angle-weighted normal computed here, on a generated glTF
//! whose file normals are themselves angle-weighted, and on a flat-shaded
//! OBJ box.

use dend::mesh::asset::normals::weighted_normals;
use dend::mesh::asset::sample::{self, TubeOptions};
use dend::mesh::asset::Asset;
use dend::mesh::io::gltf::{self as g, Container, GltfAsset, Sidecars};
use dend::mesh::io::Format;
use dend::mesh::Point;
use serde_json::Value;

fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: Point, b: Point) -> Point {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn dot(a: Point, b: Point) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn unit(a: Point) -> Point {
    let l = dot(a, a).sqrt();
    a.map(|x| x / l)
}
/// The angle between `a` and `b`, `atan2(|a × b|, a · b)` (accurate near 0).
fn angle(a: Point, b: Point) -> f64 {
    dot(cross(a, b), cross(a, b)).sqrt().atan2(dot(a, b))
}

/// The angle-weighted normal of every asset vertex `a` with a `key`: the
/// sum, over every triangle corner whose vertex has `a`'s position and key,
/// of the corner's interior angle times the triangle's unit
/// normal. Brute force, O(vertices × triangles).
fn brute_normals(pos: &[Point], tris: &[[u32; 3]], key: &[Option<[u64; 3]>]) -> Vec<Option<Point>> {
    let bits = |p: Point| p.map(|x| (x + 0.0).to_bits());
    (0..pos.len())
        .map(|a| {
            key[a]?;
            let mut s = [0.0; 3];
            for t in tris {
                let p = t.map(|i| pos[i as usize]);
                let n = unit(cross(sub(p[1], p[0]), sub(p[2], p[0])));
                for k in 0..3 {
                    let b = t[k] as usize;
                    if bits(pos[b]) == bits(pos[a]) && key[b] == key[a] {
                        let th = angle(sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
                        for c in 0..3 {
                            s[c] += th * n[c];
                        }
                    }
                }
            }
            Some(unit(s))
        })
        .collect()
}

fn key_of(n: &[Option<Point>]) -> Vec<Option<[u64; 3]>> {
    n.iter().map(|n| n.map(|n| n.map(f64::to_bits))).collect()
}

/// The GLB's JSON and BIN chunks.
fn glb_parts(bytes: &[u8]) -> (Value, Vec<u8>) {
    let u = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let jl = u(12);
    let json = serde_json::from_slice(&bytes[20..20 + jl]).unwrap();
    (json, bytes[28 + jl..28 + jl + u(20 + jl)].to_vec())
}

/// Writes `values` into VEC3 accessor `i` of `bin`.
fn write_vec3(doc: &Value, bin: &mut [u8], i: usize, values: &[Point]) {
    let a = &doc["accessors"][i];
    let v = &doc["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
    let stride = v["byteStride"].as_u64().unwrap_or(12) as usize;
    let start =
        (v["byteOffset"].as_u64().unwrap_or(0) + a["byteOffset"].as_u64().unwrap_or(0)) as usize;
    for (k, p) in values.iter().enumerate() {
        for (c, x) in p.iter().enumerate() {
            let at = start + k * stride + 4 * c;
            bin[at..at + 4].copy_from_slice(&(*x as f32).to_le_bytes());
        }
    }
}

/// The skinned sample tube (mesh space = world space) with its NORMALs
/// replaced by angle-weighted ones: smooth over the tube (across its UV
/// seam), the caps flat, hard edges at the rims.
fn weighted_tube() -> Vec<u8> {
    let input = sample::tube(TubeOptions::default()).unwrap();
    let a = GltfAsset::parse(&input, Sidecars::Refuse).unwrap();
    let n = brute_normals(a.positions(), a.triangles(), &key_of(a.normals()));
    let n: Vec<Point> = n.into_iter().map(Option::unwrap).collect();
    let (doc, mut bin) = glb_parts(&input);
    let tube = doc["accessors"][0]["count"].as_u64().unwrap() as usize;
    let tube_normal = doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"].as_u64();
    let cap_normal = doc["meshes"][0]["primitives"][1]["attributes"]["NORMAL"].as_u64();
    write_vec3(&doc, &mut bin, tube_normal.unwrap() as usize, &n[..tube]);
    write_vec3(&doc, &mut bin, cap_normal.unwrap() as usize, &n[tube..]);
    g::assemble(&serde_json::to_vec(&doc).unwrap(), bin, Container::Glb)
}

/// `[group of each corner]` by (position, file normal), for the library call.
fn corner_groups(a: &GltfAsset) -> (Vec<[u32; 3]>, usize) {
    let mut ids = std::collections::HashMap::new();
    let key = key_of(a.normals());
    let bits = |p: Point| p.map(|x| (x + 0.0).to_bits());
    let corners = a
        .triangles()
        .iter()
        .map(|t| {
            t.map(|v| {
                let next = ids.len() as u32;
                *ids.entry((bits(a.positions()[v as usize]), key[v as usize]))
                    .or_insert(next)
            })
        })
        .collect();
    (corners, ids.len())
}

#[test]
fn at_rest_the_recomputed_normals_are_the_files_angle_weighted_ones() {
    let bytes = weighted_tube();
    let a = GltfAsset::parse(&bytes, Sidecars::Refuse).unwrap();
    let (corners, groups) = corner_groups(&a);
    let w = weighted_normals(a.positions(), a.triangles(), &corners, groups);
    for (t, c) in a.triangles().iter().zip(&corners) {
        for k in 0..3 {
            let file = a.normals()[t[k] as usize].unwrap();
            let got = w[c[k] as usize].unwrap();
            assert!(angle(file, got) < 1e-6, "{file:?} vs {got:?}");
        }
    }
    // and an identity export is the file, byte for byte
    let asset = Asset::read_bytes(&bytes, Format::Glb, Sidecars::Refuse).unwrap();
    assert_eq!(
        asset.export(asset.mesh().positions(), Format::Glb).unwrap(),
        bytes
    );
}

#[test]
fn a_rigid_motion_turns_normals_and_tangents_with_it() {
    let bytes = weighted_tube();
    let asset = Asset::read_bytes(&bytes, Format::Glb, Sidecars::Refuse).unwrap();
    let rest = GltfAsset::parse(&bytes, Sidecars::Refuse).unwrap();
    // 70° about a tilted axis, plus a shift
    let r = nalgebra::Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(nalgebra::Vector3::new(1.0, 2.0, 0.5)),
        70f64.to_radians(),
    );
    let turn = |p: Point| {
        let q = r * nalgebra::Vector3::from(p);
        [q.x, q.y, q.z]
    };
    let pose: Vec<Point> = asset
        .mesh()
        .positions()
        .iter()
        .map(|&p| {
            let q = turn(p);
            [q[0] + 1.0, q[1] - 2.0, q[2] + 0.5]
        })
        .collect();
    let out = asset.export(&pose, Format::Glb).unwrap();
    let posed = GltfAsset::parse(&out, Sidecars::Refuse).unwrap();
    let mut checked = 0;
    for v in 0..rest.positions().len() {
        if let Some(n) = rest.normals()[v] {
            let got = posed.normals()[v].unwrap();
            assert!(angle(got, turn(n)) < 1e-5, "vertex {v}: {got:?}");
            checked += 1;
        }
        if let Some(t) = rest.tangents()[v] {
            assert!(
                angle(posed.tangents()[v].unwrap(), turn(t)) < 1e-5,
                "tangent {v}"
            );
        }
    }
    assert_eq!(checked, rest.positions().len());
}

#[test]
fn a_bent_asset_gets_angle_weighted_normals_with_its_hard_edges() {
    let bytes = weighted_tube();
    let asset = Asset::read_bytes(&bytes, Format::Glb, Sidecars::Refuse).unwrap();
    let rest = GltfAsset::parse(&bytes, Sidecars::Refuse).unwrap();
    // a bend that shears the tube (x += 0.3 z²): not a rotation anywhere
    // but at the bottom
    let pose: Vec<Point> = asset
        .mesh()
        .positions()
        .iter()
        .map(|p| [p[0] + 0.3 * p[2] * p[2], p[1], p[2]])
        .collect();
    let out = asset.export(&pose, Format::Glb).unwrap();
    let posed = GltfAsset::parse(&out, Sidecars::Refuse).unwrap();
    // expected: brute-force angle-weighted normals of the posed asset
    // positions, grouped by the *file's* normals
    let want = brute_normals(posed.positions(), rest.triangles(), &key_of(rest.normals()));
    let mut worst: f64 = 0.0;
    for (v, want) in want.iter().enumerate().take(rest.positions().len()) {
        let got = posed.normals()[v].unwrap();
        worst = worst.max(angle(got, want.unwrap()));
        // tangents: unit, orthogonal to the new normal, handedness kept
        if let Some(t) = posed.tangents()[v] {
            assert!(dot(t, got).abs() < 1e-5, "tangent {v} ⟂ normal");
        }
    }
    assert!(worst < 1e-5, "worst angle to the expected normal: {worst}");
    let (j0, _) = glb_parts(&bytes);
    let (j1, _) = glb_parts(&out);
    assert_eq!(j0["meshes"], j1["meshes"]);
    // hard edges stay hard: at each rim the cap's normal and the tube's
    // differ by about as much as at rest (90°), on both rims
    let (n, r) = (16, 13);
    let tube = (n + 1) * r;
    for c in 0..n {
        for (cap, side) in [(tube + 1 + c, c), (tube + n + 2 + c, (r - 1) * (n + 1) + c)] {
            let (a0, a1) = (
                angle(rest.normals()[cap].unwrap(), rest.normals()[side].unwrap()),
                angle(
                    posed.normals()[cap].unwrap(),
                    posed.normals()[side].unwrap(),
                ),
            );
            assert!((a0 - std::f64::consts::FRAC_PI_2).abs() < 1e-3);
            // (the bend tilts the top of the tube by up to 61°)
            assert!(a1 > 0.4, "rim vertex {cap}: {a1} rad after the bend");
        }
    }
    if let Some(r) = dend_testkit::gltf_validator::validate(&out, "bent.glb") {
        assert_eq!((r.errors, r.warnings), (0, 0), "{}", r.messages);
    }
}

/// A unit box with one `vn` per face (flat shading) and a `vt` seam.
const BOX: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
vn 0 0 -1\nvn 0 0 1\nvn 0 -1 0\nvn 1 0 0\nvn 0 1 0\nvn -1 0 0\n\
f 1/1/1 4/4/1 3/3/1 2/2/1\nf 5/1/2 6/2/2 7/3/2 8/4/2\nf 1/1/3 2/2/3 6/3/3 5/4/3\n\
f 2/1/4 3/2/4 7/3/4 6/4/4\nf 3/1/5 4/2/5 8/3/5 7/4/5\nf 4/1/6 1/2/6 5/3/6 8/4/6\n";

#[test]
fn obj_vn_lines_are_recomputed_per_vn_and_stay_flat() {
    let a = Asset::read_bytes(BOX.as_bytes(), Format::Obj, Sidecars::Refuse).unwrap();
    // pull one top corner out, off every face's plane: the top face (vn 2)
    // and two sides bend, none symmetrically
    let mut pose = a.mesh().positions().to_vec();
    pose[6] = [1.3, 1.2, 1.5];
    let out = String::from_utf8(a.export(&pose, Format::Obj).unwrap()).unwrap();
    let vn: Vec<Point> = out
        .lines()
        .filter_map(|l| l.strip_prefix("vn "))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    // each face's vn: the angle-weighted normal of its own two triangles
    // (the fan 0-1-2, 0-2-3 of its quad)
    let faces: [[usize; 4]; 6] = [
        [0, 3, 2, 1],
        [4, 5, 6, 7],
        [0, 1, 5, 4],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [3, 0, 4, 7],
    ];
    for (f, q) in faces.iter().enumerate() {
        let p = q.map(|i| pose[i]);
        let mut s = [0.0; 3];
        for t in [[0, 1, 2], [0, 2, 3]] {
            let n = unit(cross(sub(p[t[1]], p[t[0]]), sub(p[t[2]], p[t[0]])));
            for k in 0..3 {
                let th = angle(
                    sub(p[t[(k + 1) % 3]], p[t[k]]),
                    sub(p[t[(k + 2) % 3]], p[t[k]]),
                );
                for c in 0..3 {
                    s[c] += th * n[c];
                }
            }
        }
        assert!(
            angle(vn[f], s) < 1e-9,
            "face {f}: {:?} vs {:?}",
            vn[f],
            unit(s)
        );
    }
    // the faces away from the corner kept their vn lines exactly
    let before: Vec<&str> = BOX.lines().filter(|l| l.starts_with("vn")).collect();
    let after: Vec<&str> = out.lines().filter(|l| l.starts_with("vn")).collect();
    for f in [0, 2, 5] {
        assert_eq!(before[f], after[f], "face {f}");
    }
    // hard edges: neighbouring faces still differ by about 90°
    assert!(angle(vn[1], vn[3]) > 1.2);
}
