//! glTF/GLB and OBJ assets: the round trip keeps the file's layout and
//! attributes (measured on the generated textured, skinned, seamed tube of
//! `dend::mesh::asset::sample`), positions follow the welded pose, normals
//! keep hard edges, node transforms are inverted on write; malformed files
//! give typed errors.

use std::collections::HashSet;

use dend::deform::{Params, RotationSpec};
use dend::mesh::asset::sample::{self, TubeOptions};
use dend::mesh::asset::Asset;
use dend::mesh::io::gltf::{self as g, Container, GltfAsset, GltfError, Sidecars};
use dend::mesh::io::{Format, IoError};
use dend::mesh::{MeshError, Point};
use serde_json::{json, Value};

const AROUND: usize = 16;
const RINGS: usize = 13;

fn tube(skinned: bool, container: Container) -> Vec<u8> {
    sample::tube(TubeOptions {
        skinned,
        container,
        ..TubeOptions::default()
    })
    .unwrap()
}

/// The JSON chunk and BIN chunk of a GLB (an independent split).
fn glb_parts(bytes: &[u8]) -> (Value, Vec<u8>) {
    let u = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let jl = u(12);
    let json = serde_json::from_slice(&bytes[20..20 + jl]).unwrap();
    let bl = u(20 + jl);
    (json, bytes[28 + jl..28 + jl + bl].to_vec())
}

fn glb(json: &Value, bin: Vec<u8>) -> Vec<u8> {
    g::assemble(&serde_json::to_vec(json).unwrap(), bin, Container::Glb)
}

/// The element bytes of accessor `i` (stride gaps skipped), read with the
/// `gltf` crate's document model.
fn accessor_bytes(doc: &gltf::Document, bin: &[u8], i: usize) -> Vec<u8> {
    let a = doc.accessors().nth(i).unwrap();
    let v = a.view().unwrap();
    let elem = a.size();
    let stride = v.stride().unwrap_or(elem);
    let start = v.offset() + a.offset();
    (0..a.count())
        .flat_map(|k| bin[start + k * stride..start + k * stride + elem].to_vec())
        .collect()
}

fn f32s(bytes: &[u8], n: usize) -> Vec<Vec<f32>> {
    bytes
        .chunks(4 * n)
        .map(|c| {
            c.chunks(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect()
        })
        .collect()
}

fn twist_spec(mesh: &dend::mesh::Mesh, degrees: f64) -> dend::deform::ConstraintsSpec {
    dend_testkit::tube_spec(
        mesh,
        dend_testkit::handle(
            None,
            Some(RotationSpec::AxisAngle {
                axis: [0.0, 0.0, 1.0],
                degrees,
            }),
        ),
    )
}

#[test]
fn the_sample_reads_as_one_closed_welded_surface_in_both_containers() {
    for skinned in [true, false] {
        for container in [Container::Glb, Container::Json] {
            let f = if container == Container::Glb {
                Format::Glb
            } else {
                Format::Gltf
            };
            let a = Asset::read_bytes(&tube(skinned, container), f, Sidecars::Refuse).unwrap();
            let info = a.info();
            assert_eq!(info.asset_vertices, (AROUND + 1) * (RINGS + 2));
            assert_eq!(info.welded_vertices, AROUND * RINGS + 2);
            assert_eq!(info.triangles, 2 * AROUND * (RINGS - 1) + 2 * AROUND);
            let m = a.mesh();
            assert_eq!(m.topology().boundary_loops().len(), 0, "closed");
            assert_eq!(m.genus(), 0);
            let gl = info.gltf.unwrap();
            assert_eq!((gl.meshes, gl.primitives, gl.materials), (1, 2, 2));
            for attr in ["POSITION", "NORMAL", "TANGENT", "TEXCOORD_0"] {
                assert!(gl.attributes.iter().any(|x| x == attr), "{attr}");
            }
            assert_eq!(gl.attributes.iter().any(|x| x == "JOINTS_0"), skinned);
            assert_eq!(gl.skinned, skinned);
        }
    }
}

#[test]
fn a_twisted_skinned_glb_keeps_layout_uvs_skin_and_hard_edges() {
    let input = tube(true, Container::Glb);
    let asset = Asset::read_bytes(&input, Format::Glb, Sidecars::Refuse).unwrap();
    let (pose, rep) = dend_testkit::solve(
        asset.mesh(),
        Params::default(),
        &twist_spec(asset.mesh(), 90.0),
        40,
    );
    assert!(rep.objective.is_finite());
    let out = asset.export(&pose, Format::Glb).unwrap();

    let (j0, b0) = glb_parts(&input);
    let (j1, b1) = glb_parts(&out);
    let d0 = gltf::Document::from_json(serde_json::from_value(j0.clone()).unwrap()).unwrap();
    let d1 = gltf::Document::from_json(serde_json::from_value(j1.clone()).unwrap()).unwrap();
    assert_eq!(d0.accessors().len(), d1.accessors().len());
    let mut moved = HashSet::new();
    for p in d0.meshes().flat_map(|m| m.primitives()) {
        for s in [
            gltf::Semantic::Positions,
            gltf::Semantic::Normals,
            gltf::Semantic::Tangents,
        ] {
            if let Some(a) = p.get(&s) {
                moved.insert(a.index());
            }
        }
    }
    // every other accessor (UVs, indices, joints, weights, inverse binds) is byte-identical
    for i in 0..d0.accessors().len() {
        let (x, y) = (accessor_bytes(&d0, &b0, i), accessor_bytes(&d1, &b1, i));
        assert_eq!(x.len(), y.len(), "accessor {i}");
        if !moved.contains(&i) {
            assert_eq!(x, y, "accessor {i} changed");
        }
    }
    for key in ["materials", "skins", "nodes", "meshes", "scenes"] {
        assert_eq!(j0[key], j1[key], "{key}");
    }
    // positions: every asset vertex at its welded vertex's pose (skinned: mesh space)
    let tube_p = f32s(&accessor_bytes(&d1, &b1, 0), 3);
    let cap_p = f32s(&accessor_bytes(&d1, &b1, 4), 3);
    let all: Vec<&Vec<f32>> = tube_p.iter().chain(&cap_p).collect();
    assert_eq!(all.len(), asset.to_welded().len());
    for (a, p) in all.iter().enumerate() {
        let w = pose[asset.to_welded()[a] as usize];
        assert_eq!(**p, w.map(|x| x as f32).to_vec(), "asset vertex {a}");
    }
    // min/max match the written positions
    let mx = j1["accessors"][0]["max"].as_array().unwrap();
    for k in 0..3 {
        let hi = tube_p.iter().map(|p| p[k]).fold(f32::MIN, f32::max);
        assert_eq!(mx[k].as_f64().unwrap(), f64::from(hi));
    }
    // the twist moved the top: positions did change
    assert!(dend_testkit::max_dist(&pose, asset.mesh().positions()) > 0.3);

    let tube_n = f32s(&accessor_bytes(&d1, &b1, 1), 3);
    let cap_n = f32s(&accessor_bytes(&d1, &b1, 5), 3);
    let tan = f32s(&accessor_bytes(&d1, &b1, 2), 4);
    let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| f64::from(x * y)).sum::<f64>();
    for k in 0..RINGS {
        // UV seam: the u = 0 and u = 1 copies keep one normal, bit for bit
        let (a, b) = (k * (AROUND + 1), k * (AROUND + 1) + AROUND);
        assert_eq!(tube_n[a], tube_n[b], "ring {k} seam normal");
        assert_eq!(tube_p[a], tube_p[b], "ring {k} seam position");
        for c in 0..=AROUND {
            let i = k * (AROUND + 1) + c;
            assert!((dot(&tube_n[i], &tube_n[i]) - 1.0).abs() < 1e-5);
            assert!(
                dot(&tube_n[i], &tan[i][..3]).abs() < 1e-5,
                "tangent ⟂ normal"
            );
            assert_eq!(tan[i][3], 1.0, "handedness kept");
        }
    }
    // hard edges: cap rim normals stay perpendicular to the tube's there
    for c in 0..AROUND {
        let bottom = (1 + c, c);
        let top = (AROUND + 2 + c, (RINGS - 1) * (AROUND + 1) + c);
        for (cap, side) in [bottom, top] {
            assert!(dot(&cap_n[cap], &tube_n[side]).abs() < 1e-3, "rim {c}");
        }
        // the top cap turned with the handle about z: still facing +z
        assert!(cap_n[AROUND + 2 + c][2] > 0.999);
    }
    // the middle of the twisted tube: normals follow the surface (compared
    // with the area-weighted normals of the welded pose)
    let welded = asset.mesh();
    let mut sums = vec![[0.0f64; 3]; welded.num_vertices()];
    for t in welded.triangles() {
        let [a, b, c] = t.map(|i| pose[i as usize]);
        let n = dend::mesh::cross(dend::mesh::sub(b, a), dend::mesh::sub(c, a));
        for &i in t {
            for k in 0..3 {
                sums[i as usize][k] += n[k];
            }
        }
    }
    let k = RINGS / 2;
    for c in 0..AROUND {
        let i = k * (AROUND + 1) + c;
        let s = sums[asset.to_welded()[i] as usize];
        let len = dend::mesh::norm(s);
        let cos = dot(&tube_n[i], &s.map(|x| (x / len) as f32));
        assert!(cos > 0.995, "ring {k} column {c}: cos {cos}");
    }
}

#[test]
fn identity_export_returns_the_asset_unchanged() {
    for container in [Container::Glb, Container::Json] {
        let f = if container == Container::Glb {
            Format::Glb
        } else {
            Format::Gltf
        };
        let input = tube(true, container);
        let a = Asset::read_bytes(&input, f, Sidecars::Refuse).unwrap();
        let out = a.export(a.mesh().positions(), f).unwrap();
        assert_eq!(out, input, "{f}");
    }
}

#[test]
fn node_transforms_are_applied_on_read_and_inverted_on_write() {
    let input = tube(false, Container::Json);
    let a = Asset::read_bytes(&input, Format::Gltf, Sidecars::Refuse).unwrap();
    // local (0.5, 0, 0) → scale (1, 2, 0.5) → rotate x→y→z→x → + (1, 2, 3)
    let p0 = a.positions()[0];
    assert!(
        dend_testkit::max_dist(&[p0], &[[1.0, 2.5, 3.0]]) < 1e-6,
        "{p0:?}"
    );
    // a rigid quarter turn about world z, then a shift: positions and normals follow
    let rot = |p: Point| [-p[1] + 0.25, p[0], p[2]];
    let pose: Vec<Point> = a.mesh().positions().iter().map(|&p| rot(p)).collect();
    let out = a.export(&pose, Format::Glb).unwrap();
    let back = Asset::read_bytes(&out, Format::Glb, Sidecars::Refuse).unwrap();
    assert_eq!(back.positions().len(), a.positions().len());
    let want: Vec<Point> = a.positions().iter().map(|&p| rot(p)).collect();
    assert!(dend_testkit::max_dist(back.positions(), &want) < 1e-5);
    let before = GltfAsset::parse(&input, Sidecars::Refuse).unwrap();
    let after = GltfAsset::parse(&out, Sidecars::Refuse).unwrap();
    for (n0, n1) in before.normals().iter().zip(after.normals()) {
        let (n0, n1) = (n0.unwrap(), n1.unwrap());
        // a rigid motion turns every normal by its rotation
        let turned = [-n0[1], n0[0], n0[2]];
        assert!(
            dend_testkit::max_dist(&[turned], &[n1]) < 1e-6,
            "{n0:?} → {n1:?}"
        );
    }
}

#[test]
fn gltf_with_a_side_car_buffer_reads_like_the_glb() {
    let dir = tempfile::tempdir().unwrap();
    let (mut json, bin) = glb_parts(&tube(true, Container::Glb));
    std::fs::write(dir.path().join("tube.bin"), &bin).unwrap();
    json["buffers"][0]["uri"] = json!("tube.bin");
    let path = dir.path().join("tube.gltf");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    let side = Asset::read_path(&path).unwrap();
    let glb =
        Asset::read_bytes(&tube(true, Container::Glb), Format::Glb, Sidecars::Refuse).unwrap();
    assert_eq!(side.positions(), glb.positions());
    assert_eq!(side.triangles(), glb.triangles());
    // without a folder (uploads) side-car files are refused
    let e = GltfAsset::parse(&std::fs::read(&path).unwrap(), Sidecars::Refuse).unwrap_err();
    assert!(
        matches!(e, GltfError::ExternalBuffer { buffer: 0, .. }),
        "{e}"
    );
}

/// The sample GLB with its JSON changed by `f`.
fn mutated(f: impl FnOnce(&mut Value)) -> Vec<u8> {
    let (mut json, bin) = glb_parts(&tube(true, Container::Glb));
    f(&mut json);
    glb(&json, bin)
}

fn parse_err(bytes: &[u8]) -> GltfError {
    GltfAsset::parse(bytes, Sidecars::Refuse).unwrap_err()
}

#[test]
fn malformed_gltf_gives_typed_errors() {
    let good = tube(true, Container::Glb);
    for n in (0..good.len()).step_by(41) {
        assert!(
            GltfAsset::parse(&good[..n], Sidecars::Refuse).is_err(),
            "prefix {n}"
        );
    }
    assert!(matches!(parse_err(b"{\"asset\": "), GltfError::Json { .. }));
    assert!(matches!(
        parse_err(b"glTF\x02\0\0\0\xff\xff\xff\x7f"),
        GltfError::Glb { offset: 8, .. }
    ));
    let e = parse_err(&mutated(|j| {
        j["buffers"][0]["byteLength"] = json!(1u64 << 30)
    }));
    assert!(
        matches!(
            e,
            GltfError::BufferTooShort {
                declared: 1_073_741_824,
                ..
            }
        ),
        "{e}"
    );
    let e = parse_err(&mutated(|j| {
        j["meshes"][0]["primitives"][0]["mode"] = json!(1)
    }));
    assert!(matches!(e, GltfError::Unsupported { .. }), "{e}");
    let e = parse_err(&mutated(|j| {
        j["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
        j["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    }));
    assert!(
        matches!(e, GltfError::Unsupported { ref what } if what.contains("draco")),
        "{e}"
    );
    let e = parse_err(&mutated(|j| j["accessors"][0]["type"] = json!("VEC2")));
    assert!(matches!(e, GltfError::Accessor { accessor: 0, .. }), "{e}");
    let e = parse_err(&mutated(|j| {
        j["accessors"][0]["componentType"] = json!(5121)
    }));
    assert!(matches!(e, GltfError::Accessor { accessor: 0, .. }), "{e}");
    let e = parse_err(&mutated(|j| {
        j["accessors"][0]["componentType"] = json!(5130)
    }));
    assert!(matches!(e, GltfError::Invalid { .. }), "{e}");
    let e = parse_err(&mutated(|j| {
        j["accessors"][3]["byteOffset"] = json!(1_000_000)
    }));
    assert!(
        matches!(e, GltfError::Accessor { .. } | GltfError::Invalid { .. }),
        "{e}"
    );
    let e = parse_err(&mutated(|j| j["accessors"][0]["count"] = json!(100_000)));
    assert!(matches!(e, GltfError::Accessor { accessor: 0, .. }), "{e}");
    let e = parse_err(&mutated(|j| {
        j["accessors"][0]["sparse"] = json!({
            "count": 1,
            "indices": {"bufferView": 6, "componentType": 5123},
            "values": {"bufferView": 2}
        })
    }));
    assert!(
        matches!(e, GltfError::Unsupported { .. } | GltfError::Invalid { .. }),
        "{e}"
    );
    let e = parse_err(&mutated(|j| j["nodes"][2]["children"] = json!([1])));
    assert!(matches!(e, GltfError::Invalid { .. }), "{e}");
    // a skinned mesh ignores its node's matrix; an unskinned one cannot
    let zero = |j: &mut Value| j["nodes"][0]["matrix"] = json!(vec![0.0; 16]);
    assert!(GltfAsset::parse(&mutated(zero), Sidecars::Refuse).is_ok());
    let e = parse_err(&mutated(|j| {
        zero(j);
        j["nodes"][0].as_object_mut().unwrap().remove("skin");
        j.as_object_mut().unwrap().remove("skins");
    }));
    assert!(matches!(e, GltfError::SingularTransform { node: 0 }), "{e}");
    // accessor indices out of range in a primitive: gltf-json's validation
    // would index with them (a panic the no_panic proptest found)
    for attr in ["POSITION", "NORMAL", "TEXCOORD_0"] {
        let e = parse_err(&mutated(|j| {
            j["meshes"][0]["primitives"][0]["attributes"][attr] = json!(999)
        }));
        assert!(matches!(e, GltfError::Invalid { .. }), "{attr}: {e}");
    }
    let e = parse_err(&mutated(|j| {
        j["meshes"][0]["primitives"][0]["indices"] = json!(999)
    }));
    assert!(matches!(e, GltfError::Invalid { .. }), "{e}");
    // a NORMAL accessor shorter than POSITION (the spec wants equal counts;
    // the no_panic proptest found the panic it caused in the export)
    let e = parse_err(&mutated(|j| {
        let n = j["meshes"][0]["primitives"][0]["attributes"]["NORMAL"]
            .as_u64()
            .unwrap() as usize;
        j["accessors"][n]["count"] = json!(2);
    }));
    assert!(matches!(e, GltfError::Invalid { .. }), "{e}");
}

#[test]
fn bad_values_in_the_buffers_give_typed_errors() {
    let (json, bin) = glb_parts(&tube(true, Container::Glb));
    // an index past the caps' vertex count (u8 indices in bufferView 7)
    let mut b = bin.clone();
    let at = json["bufferViews"][7]["byteOffset"].as_u64().unwrap() as usize;
    b[at] = 200;
    let e = parse_err(&glb(&json, b));
    assert!(
        matches!(
            e,
            GltfError::IndexOutOfRange {
                mesh: 0,
                primitive: 1,
                index: 200,
                ..
            }
        ),
        "{e}"
    );
    // a NaN position: parsed, then refused by mesh validation
    let mut b = bin;
    b[0..4].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = Asset::read_bytes(&glb(&json, b), Format::Glb, Sidecars::Refuse).unwrap_err();
    assert!(
        matches!(e, IoError::Mesh(MeshError::NonFinite { .. })),
        "{e}"
    );
}

#[test]
fn an_obj_asset_keeps_its_lines_and_rewrites_v_and_vn() {
    let mut spec = dend::mesh::gen::ShapeSpec::default_for(dend::mesh::gen::Shape::Bar);
    spec.params.nu = Some(3);
    spec.params.nv = Some(9);
    let m = dend::mesh::gen::generate(&spec).unwrap();
    let mut obj = String::from("# made by the test\nmtllib bar.mtl\no bar\n");
    for p in m.positions() {
        obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for p in m.positions() {
        obj += &format!("vt {} {}\n", p[0], p[2] / 6.0);
    }
    obj += "vn 0 0 1\nvn 1 0 0\ng side\nusemtl steel\ns 1\n";
    for (i, t) in m.triangles().iter().enumerate() {
        let [a, b, c] = t.map(|v| v + 1);
        let n = 1 + i % 2;
        obj += &format!("f {a}/{a}/{n} {b}/{b}/{n} {c}/{c}/{n}\n");
    }
    let a = Asset::read_bytes(obj.as_bytes(), Format::Obj, Sidecars::Refuse).unwrap();
    assert_eq!(a.info().welded_vertices, m.num_vertices());
    assert_eq!(a.info().name.as_deref(), Some("bar"));
    assert_eq!(
        a.export(a.mesh().positions(), Format::Obj).unwrap(),
        obj.as_bytes()
    );
    let (pose, _) =
        dend_testkit::solve(a.mesh(), Params::default(), &twist_spec(a.mesh(), 60.0), 20);
    let out = String::from_utf8(a.export(&pose, Format::Obj).unwrap()).unwrap();
    let (before, after): (Vec<&str>, Vec<&str>) = (obj.lines().collect(), out.lines().collect());
    assert_eq!(before.len(), after.len());
    let mut v = 0;
    for (x, y) in before.iter().zip(&after) {
        if x.starts_with("v ") {
            let p: Vec<f64> = y
                .split_whitespace()
                .skip(1)
                .map(|t| t.parse().unwrap())
                .collect();
            assert_eq!(p, pose[v].to_vec());
            v += 1;
        } else if x.starts_with("vn ") {
            let n: Vec<f64> = y
                .split_whitespace()
                .skip(1)
                .map(|t| t.parse().unwrap())
                .collect();
            assert!((n.iter().map(|c| c * c).sum::<f64>() - 1.0).abs() < 1e-9);
        } else {
            assert_eq!(x, y);
        }
    }
    assert_eq!(v, m.num_vertices());
}

#[test]
fn a_ply_asset_keeps_its_extra_vertex_properties() {
    let mut spec = dend::mesh::gen::ShapeSpec::default_for(dend::mesh::gen::Shape::Bar);
    spec.params.nu = Some(3);
    spec.params.nv = Some(9);
    let m = dend::mesh::gen::generate(&spec).unwrap();
    let mut ply = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty float s\nproperty float t\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        m.num_vertices(),
        m.num_triangles()
    )
    .into_bytes();
    let header = ply.len();
    for (i, p) in m.positions().iter().enumerate() {
        p.iter().for_each(|x| ply.extend((*x as f32).to_le_bytes()));
        ply.push(i as u8);
        ply.extend((p[0] as f32).to_le_bytes());
        ply.extend((p[2] as f32 / 6.0).to_le_bytes());
    }
    for t in m.triangles() {
        ply.push(3);
        t.iter().for_each(|i| ply.extend(i.to_le_bytes()));
    }
    let a = Asset::read_bytes(&ply, Format::Ply, Sidecars::Refuse).unwrap();
    assert_eq!(a.info().attributes, vec!["red", "s", "t"]);
    assert_eq!(a.export(a.mesh().positions(), Format::Ply).unwrap(), ply);
    let (pose, _) =
        dend_testkit::solve(a.mesh(), Params::default(), &twist_spec(a.mesh(), 60.0), 20);
    let out = a.export(&pose, Format::Ply).unwrap();
    assert_eq!(out.len(), ply.len());
    // only x y z bytes changed: the 9 bytes of red, s, t after each vertex's 12
    let stride = 12 + 9;
    for v in 0..m.num_vertices() {
        let at = header + v * stride + 12;
        assert_eq!(out[at..at + 9], ply[at..at + 9], "vertex {v} extras");
    }
    let faces = header + m.num_vertices() * stride;
    assert_eq!(out[faces..], ply[faces..]);
    let back = Asset::read_bytes(&out, Format::Ply, Sidecars::Refuse).unwrap();
    let want: Vec<Point> = pose.iter().map(|p| p.map(|x| x as f32 as f64)).collect();
    assert_eq!(back.positions(), &want[..]);
}
