//! Rigged assets through the server: the skeleton in `GET /v1/meshes/{id}`,
//! joint selectors, and poses exported onto the rig
//! (`…/export?format=glb&as=skeleton[-animation]`) on the generated limb.
//!
//! The exports are read back independently of the fit: the nodes' TRS and
//! the inverse bind matrices give each joint's skinning matrix, the
//! corrective target is added to the bind positions, and linear blend
//! skinning is computed here; that must be the solved pose within 1e-4 of
//! the diagonal. The Khronos validator finds no error.

use std::time::Duration;

use dend::mesh::asset::Asset;
use dend::mesh::io::gltf::Sidecars;
use dend::mesh::io::Format;
use dend::rig::sample::{limb, LimbOptions};
use dend_client::constraints::{JointSel, NameOrIndex};
use dend_client::ws::DeltaJson;
use dend_client::{
    Client, ClientError, ConstraintsSpec, GenerateMesh, HandleSpec, SavePose, SessionClient,
    SessionParams, ShapeParams, VertexSet,
};
use dend_server::Config;
use dend_testkit::server::start;
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3, Vector4};
use serde_json::{json, Value};

fn glb_parts(bytes: &[u8]) -> (Value, Vec<u8>) {
    let u = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let jl = u(12);
    let json = serde_json::from_slice(&bytes[20..20 + jl]).unwrap();
    let bl = u(20 + jl);
    (json, bytes[28 + jl..28 + jl + bl].to_vec())
}

/// Accessor `a`'s floats (`n` per element).
fn floats(doc: &Value, bin: &[u8], a: usize, n: usize) -> Vec<Vec<f32>> {
    let acc = &doc["accessors"][a];
    let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let start = view["byteOffset"].as_u64().unwrap_or(0) as usize
        + acc["byteOffset"].as_u64().unwrap_or(0) as usize;
    let stride = view["byteStride"].as_u64().map_or(4 * n, |s| s as usize);
    (0..acc["count"].as_u64().unwrap() as usize)
        .map(|k| {
            (0..n)
                .map(|c| {
                    let at = start + k * stride + 4 * c;
                    f32::from_le_bytes(bin[at..at + 4].try_into().unwrap())
                })
                .collect()
        })
        .collect()
}

fn trs(node: &Value) -> Matrix4<f64> {
    let get = |k: &str, d: &[f64]| -> Vec<f64> {
        node.get(k)
            .and_then(Value::as_array)
            .map_or(d.to_vec(), |a| {
                a.iter().map(|x| x.as_f64().unwrap()).collect()
            })
    };
    let t = get("translation", &[0.0; 3]);
    let r = get("rotation", &[0.0, 0.0, 0.0, 1.0]);
    let s = get("scale", &[1.0; 3]);
    let q = UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2]));
    Matrix4::new_translation(&Vector3::new(t[0], t[1], t[2]))
        * q.to_homogeneous()
        * Matrix4::new_nonuniform_scaling(&Vector3::new(s[0], s[1], s[2]))
}

/// The skinned positions (POSITION plus `target_weight` × the last morph
/// target) of the limb export `doc`, computed here.
fn skinned(doc: &Value, bin: &[u8], target_weight: f64) -> Vec<[f64; 3]> {
    let nodes = doc["nodes"].as_array().unwrap();
    let mut parent = vec![None; nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        for c in n["children"].as_array().into_iter().flatten() {
            parent[c.as_u64().unwrap() as usize] = Some(i);
        }
    }
    let global = |mut i: usize| {
        let mut m = trs(&nodes[i]);
        while let Some(p) = parent[i] {
            m = trs(&nodes[p]) * m;
            i = p;
        }
        m
    };
    let skin = &doc["skins"][0];
    let ibm = floats(
        doc,
        bin,
        skin["inverseBindMatrices"].as_u64().unwrap() as usize,
        16,
    );
    let joints: Vec<Matrix4<f64>> = skin["joints"]
        .as_array()
        .unwrap()
        .iter()
        .zip(&ibm)
        .map(|(j, m)| {
            let ibm = Matrix4::from_fn(|r, c| f64::from(m[c * 4 + r]));
            global(j.as_u64().unwrap() as usize) * ibm
        })
        .collect();
    let prim = &doc["meshes"][0]["primitives"][0];
    let at = |k: &str| prim["attributes"][k].as_u64().unwrap() as usize;
    let pos = floats(doc, bin, at("POSITION"), 3);
    let weights = floats(doc, bin, at("WEIGHTS_0"), 4);
    // JOINTS_0 is u16 ×4 in the limb
    let jacc = &doc["accessors"][at("JOINTS_0")];
    let jview = &doc["bufferViews"][jacc["bufferView"].as_u64().unwrap() as usize];
    let jstart = jview["byteOffset"].as_u64().unwrap_or(0) as usize;
    let target = prim["targets"]
        .as_array()
        .and_then(|t| t.last())
        .map(|t| floats(doc, bin, t["POSITION"].as_u64().unwrap() as usize, 3));
    (0..pos.len())
        .map(|i| {
            let mut v = Vector4::new(
                f64::from(pos[i][0]),
                f64::from(pos[i][1]),
                f64::from(pos[i][2]),
                1.0,
            );
            if let Some(t) = &target {
                for c in 0..3 {
                    v[c] += target_weight * f64::from(t[i][c]);
                }
            }
            let mut out = Vector4::zeros();
            for (c, w) in weights[i].iter().enumerate() {
                let at = jstart + 8 * i + 2 * c;
                let j = u16::from_le_bytes([bin[at], bin[at + 1]]) as usize;
                out += joints[j] * v * f64::from(*w);
            }
            [out.x, out.y, out.z]
        })
        .collect()
}

async fn export(s: &SessionClient, base: &str, query: &str) -> reqwest::Response {
    reqwest::Client::new()
        .get(format!("{base}/v1/sessions/{}/export?{query}", s.id))
        .bearer_auth(&s.token)
        .send()
        .await
        .unwrap()
}

fn header(r: &reqwest::Response, name: &str) -> f64 {
    r.headers()[name].to_str().unwrap().parse().unwrap()
}

/// The angle (degrees) of node `n`'s rotation in `doc` away from identity
/// (the limb's rest rotations are identity), and about which axis.
fn turn(doc: &Value, n: usize) -> (f64, Vector3<f64>) {
    let r: Vec<f64> = doc["nodes"][n]["rotation"]
        .as_array()
        .map_or(vec![0.0, 0.0, 0.0, 1.0], |a| {
            a.iter().map(|x| x.as_f64().unwrap()).collect()
        });
    let q = UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2]));
    let axis = q.axis().map_or(Vector3::z(), |a| a.into_inner());
    (q.angle().to_degrees(), axis)
}

/// `bone0` held, the handle `name` on `joint` and its children, turning
/// about `pivot`.
fn limb_spec(name: &str, joint: &str, pivot: [f64; 3]) -> ConstraintsSpec {
    let handle = HandleSpec {
        pivot: Some(pivot),
        ..HandleSpec::named(name, VertexSet::joint(joint, true))
    };
    ConstraintsSpec::new(VertexSet::joint("bone0", false), vec![handle])
}

async fn session(
    c: &Client,
    input: Vec<u8>,
    spec: ConstraintsSpec,
) -> Result<(SessionClient, Value), ClientError> {
    let mesh = c.upload_file(input, "glb").await?;
    let info = serde_json::to_value(&mesh).unwrap();
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    s.set_constraints(&spec).await?;
    s.wait_ready(Duration::from_secs(120)).await?;
    Ok((s, info))
}

#[tokio::test]
async fn a_joint_dragged_by_its_region_is_recovered_from_the_export() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    // rigid skinning: the drag's pose is exactly a rig pose
    let input = limb(LimbOptions {
        blend: 0.0,
        ..LimbOptions::default()
    });
    let spec = limb_spec("arm", "bone1", [0.0, 1.0, 0.0]);
    let (s, info) = session(&c, input.clone(), spec).await?;
    // the skeleton is listed
    let joints = info["asset"]["skeleton"]["joints"].as_array().unwrap();
    let names: Vec<&str> = joints.iter().map(|j| j["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["bone0", "bone1", "bone2", "end"]);
    assert_eq!(joints[2]["parent"], "bone1");
    assert!((joints[1]["head"][1].as_f64().unwrap() - 1.0).abs() < 1e-6);
    s.drag(
        "arm",
        DeltaJson::axis_angle([0.0, 0.0, 1.0], 40.0),
        Some(40),
    )
    .await?;
    let r = export(&s, &base, "format=glb&as=skeleton").await;
    assert_eq!(r.status(), 200);
    let max = header(&r, "x-dend-fit-residual-max");
    assert!(max < 1e-3, "residual {max}");
    let out = r.bytes().await?.to_vec();
    let (doc, _) = glb_parts(&out);
    // nodes 2.. are bone0, bone1, bone2, end
    let (a1, axis) = turn(&doc, 3);
    assert!(
        (a1 - 40.0).abs() < 1.0 && axis.z > 0.99,
        "bone1 turned {a1}° about {axis}"
    );
    for n in [2, 4, 5] {
        assert!(
            turn(&doc, n).0 < 0.1,
            "node {n} turned {}°",
            turn(&doc, n).0
        );
    }
    if let Some(rep) = dend_testkit::gltf_validator::validate(&out, "skeleton.glb") {
        assert_eq!(rep.errors, 0, "{}", rep.messages);
    }
    // pose=rest: the rest positions of the posed session (what a client
    // joining it carries a joint's head from); only with as=pose
    let r = export(&s, &base, "format=obj&pose=rest").await;
    assert_eq!(r.status(), 200);
    let text = r.text().await?;
    let got: Vec<[f64; 3]> = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    let rest = Asset::read_bytes(&input, Format::Glb, Sidecars::Refuse).unwrap();
    assert!(dend_testkit::max_dist(&got, rest.mesh().positions()) < 1e-6);
    let now = export(&s, &base, "format=obj").await.text().await?;
    assert_ne!(now, text, "the current pose is not the rest");
    for q in ["format=glb&as=skeleton&pose=rest", "format=obj&pose=later"] {
        let r = export(&s, &base, q).await;
        assert_eq!(r.status(), 400, "{q}");
        assert_eq!(r.json::<Value>().await?["code"], "invalid_query", "{q}");
    }
    Ok(())
}

#[tokio::test]
async fn a_dend_pose_is_reproduced_by_skeleton_and_corrective() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let input = limb(LimbOptions::default());
    let asset = Asset::read_bytes(&input, Format::Glb, Sidecars::Refuse).unwrap();
    let diag = {
        let (lo, hi) = asset.mesh().bounding_box();
        (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
    };
    let spec = limb_spec("hand", "bone2", [0.0, 2.0, 0.0]);
    let (s, _) = session(&c, input, spec).await?;
    let http = reqwest::Client::new();
    let mut solved = vec![];
    for (name, d) in [
        ("bend", DeltaJson::axis_angle([0.0, 0.0, 1.0], 50.0)),
        ("twist", DeltaJson::axis_angle([1.0, 0.0, 0.0], -35.0)),
    ] {
        let p = s.drag("hand", d, Some(60)).await?;
        let save = SavePose {
            name: name.to_owned(),
            replace: false,
        };
        let r = http
            .post(format!("{base}/v1/sessions/{}/poses", s.id))
            .bearer_auth(&s.token)
            .json(&save)
            .send()
            .await?;
        assert_eq!(r.status(), 201);
        solved.push(asset.asset_pose(&p.positions).unwrap());
    }
    // the current pose, as=skeleton with its corrective at weight 1
    let r = export(&s, &base, "format=glb&as=skeleton").await;
    assert_eq!(r.status(), 200);
    let (max, mean) = (
        header(&r, "x-dend-fit-residual-max"),
        header(&r, "x-dend-fit-residual-mean"),
    );
    eprintln!("skeleton fit of a DEND pose: residual max {max:.2e}, mean {mean:.2e}");
    assert!(mean <= max && max > 0.0);
    let out = r.bytes().await?.to_vec();
    let (doc, bin) = glb_parts(&out);
    assert_eq!(doc["meshes"][0]["weights"], json!([1.0]));
    assert_eq!(doc["meshes"][0]["extras"]["targetNames"], json!(["pose"]));
    let drawn = skinned(&doc, &bin, 1.0);
    let worst = dend_testkit::max_dist(&drawn, &solved[1]) / diag;
    assert!(
        worst < 1e-4,
        "skeleton + corrective is {worst} of the diagonal off"
    );
    // without the corrective weight the residual is the fit's
    let bare = dend_testkit::max_dist(&skinned(&doc, &bin, 0.0), &solved[1]) / diag;
    assert!((bare - max).abs() < 1e-5, "{bare} vs {max}");
    if let Some(rep) = dend_testkit::gltf_validator::validate(&out, "skeleton.glb") {
        assert_eq!(rep.errors, 0, "{}", rep.messages);
    }
    // corrective=false: no target
    let r = export(&s, &base, "format=glb&as=skeleton&corrective=false").await;
    let (doc, _) = glb_parts(&r.bytes().await?);
    assert!(doc["meshes"][0]["primitives"][0].get("targets").is_none());
    // the animation: one keyframe per named pose, both poses' correctives
    let r = export(&s, &base, "format=glb&as=skeleton-animation").await;
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-dend-fit-poses"], "2");
    let out = r.bytes().await?.to_vec();
    let (doc, _) = glb_parts(&out);
    let anim = &doc["animations"][0];
    assert_eq!(anim["name"], "poses");
    assert_eq!(
        doc["meshes"][0]["extras"]["targetNames"],
        json!(["bend", "twist"])
    );
    let input_acc = anim["samplers"][0]["input"].as_u64().unwrap() as usize;
    assert_eq!(doc["accessors"][input_acc]["count"], 2);
    let paths: Vec<&str> = anim["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["target"]["path"].as_str().unwrap())
        .collect();
    assert!(paths.contains(&"rotation") && paths.contains(&"weights"));
    if let Some(rep) = dend_testkit::gltf_validator::validate(&out, "animation.glb") {
        assert_eq!(rep.errors, 0, "{}", rep.messages);
    }
    Ok(())
}

#[tokio::test]
async fn rig_errors_are_typed() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let input = limb(LimbOptions::default());
    let mesh = c.upload_file(input, "glb").await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    let http = reqwest::Client::new();
    let put = |spec: ConstraintsSpec| {
        http.put(format!("{base}/v1/sessions/{}/constraints", s.id))
            .bearer_auth(&s.token)
            .json(&spec)
            .send()
    };
    let r = put(ConstraintsSpec::new(
        VertexSet::joint("hand.L", false),
        vec![],
    ))
    .await?;
    assert_eq!(r.status(), 422);
    let e: Value = r.json().await?;
    assert_eq!(e["code"], "unknown_joint");
    assert!(e["message"].as_str().unwrap().contains("bone1"), "{e}");
    // a mesh without a skin: not_skinned, for selectors and exports
    let tube = dend::mesh::asset::sample::tube(dend::mesh::asset::sample::TubeOptions {
        skinned: false,
        ..Default::default()
    })
    .unwrap();
    let m2 = c.upload_file(tube, "glb").await?;
    let s2 = c.create_session(&m2.id, SessionParams::default()).await?;
    let r = http
        .put(format!("{base}/v1/sessions/{}/constraints", s2.id))
        .bearer_auth(&s2.token)
        .json(&ConstraintsSpec::new(
            VertexSet::Joint(JointSel {
                joint: NameOrIndex::Index(0),
                with_children: false,
            }),
            vec![],
        ))
        .send()
        .await?;
    assert_eq!(r.status(), 422);
    assert_eq!(r.json::<Value>().await?["code"], "not_skinned");
    let r = export(&s2, &base, "format=glb&as=skeleton").await;
    assert_eq!(r.status(), 422);
    assert_eq!(r.json::<Value>().await?["code"], "not_skinned");
    // a skeleton export is glTF/GLB; corrective= is a boolean
    let r = export(&s, &base, "format=obj&as=skeleton").await;
    assert_eq!(r.json::<Value>().await?["code"], "unsupported_export");
    let r = export(&s, &base, "format=glb&as=skeleton&corrective=maybe").await;
    assert_eq!(r.json::<Value>().await?["code"], "invalid_query");
    Ok(())
}

#[test]
fn the_cli_writes_the_skeleton_beside_the_pose() {
    let dir = tempfile::tempdir().unwrap();
    let (input, posed, rig, c) = (
        dir.path().join("limb.glb"),
        dir.path().join("posed.glb"),
        dir.path().join("rig.glb"),
        dir.path().join("c.json"),
    );
    std::fs::write(&input, limb(LimbOptions::default())).unwrap();
    std::fs::write(
        &c,
        r#"{"fixed": {"joint": "bone0"},
            "handles": [{"name": "hand", "vertices": {"joint": "bone2", "with_children": true},
                         "pivot": [0, 2, 0], "rotate": {"axis": [0, 0, 1], "degrees": 45}}]}"#,
    )
    .unwrap();
    let s = |p: &std::path::Path| p.to_str().unwrap().to_owned();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dend"))
        .args([
            "deform",
            &s(&input),
            "--constraints",
            &s(&c),
            "-o",
            &s(&posed),
        ])
        .args(["--output-skeleton", &s(&rig)])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("skeleton fit: residual max"), "{err}");
    // the skeleton file, skinned here, is the posed file's pose
    let (doc, bin) = glb_parts(&std::fs::read(&rig).unwrap());
    let drawn = skinned(&doc, &bin, 1.0);
    let posed_asset =
        dend::mesh::io::gltf::GltfAsset::parse(&std::fs::read(&posed).unwrap(), Sidecars::Refuse)
            .unwrap();
    let worst = dend_testkit::max_dist(&drawn, posed_asset.positions());
    assert!(worst < 1e-4 * 4.0, "{worst}");
    // a mesh without a skin: a clear error, exit status 2 or 1, no panic
    let tube = dir.path().join("tube.glb");
    std::fs::write(
        &tube,
        dend::mesh::asset::sample::tube(dend::mesh::asset::sample::TubeOptions {
            skinned: false,
            ..Default::default()
        })
        .unwrap(),
    )
    .unwrap();
    std::fs::write(&c, r#"{"fixed": [0, 1, 2], "handles": []}"#).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dend"))
        .args([
            "deform",
            &s(&tube),
            "--constraints",
            &s(&c),
            "-o",
            &s(&posed),
        ])
        .args(["--output-skeleton", &s(&rig)])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not skinned"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[tokio::test]
async fn the_generated_limb_is_a_rigged_asset_with_its_default_edit() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let http = reqwest::Client::new();
    let r = http
        .post(format!("{base}/v1/meshes/generate"))
        .json(&GenerateMesh::new("limb"))
        .send()
        .await?;
    assert_eq!(r.status(), 201);
    let m: Value = r.json().await?;
    assert_eq!(m["vertices"], 302);
    let joints = m["asset"]["skeleton"]["joints"].as_array().unwrap();
    let names: Vec<&str> = joints.iter().map(|j| j["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["bone0", "bone1", "bone2", "end"]);
    // the default edit: bone0's region fixed, bone2 and end a handle about
    // bone2's head, as index lists
    let c = &m["constraints"];
    assert_eq!(c["fixed"], joints[0]["region"]);
    let h = &c["handles"][0];
    assert_eq!(h["name"], "bone2");
    assert_eq!(h["pivot"], json!([0.0, 2.0, 0.0]));
    assert_eq!(
        h["vertices"], joints[2]["region"],
        "end has no vertex of its own"
    );
    // it poses and exports onto its rig like an upload
    let c2 = Client::new(&base);
    let s = c2
        .create_session(m["id"].as_str().unwrap(), SessionParams::default())
        .await?;
    s.set_constraints(&serde_json::from_value::<ConstraintsSpec>(c.clone()).unwrap())
        .await?;
    s.wait_ready(Duration::from_secs(120)).await?;
    s.drag(
        "bone2",
        DeltaJson::axis_angle([0.0, 0.0, 1.0], 30.0),
        Some(40),
    )
    .await?;
    let r = export(&s, &base, "format=glb&as=skeleton").await;
    assert_eq!(r.status(), 200);
    // parameters out of range are 422 invalid_params, not a panic
    let r = http
        .post(format!("{base}/v1/meshes/generate"))
        .json(&GenerateMesh {
            params: ShapeParams {
                nu: Some(0),
                ..ShapeParams::default()
            },
            ..GenerateMesh::new("limb")
        })
        .send()
        .await?;
    assert_eq!(r.status(), 422);
    assert_eq!(r.json::<Value>().await?["code"], "invalid_params");
    Ok(())
}

#[test]
fn dend_gen_writes_the_limb_with_its_skin() {
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("limb.glb");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dend"))
        .args(["gen", "limb", "--nu", "4", "-o", glb.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let asset =
        Asset::read_bytes(&std::fs::read(&glb).unwrap(), Format::Glb, Sidecars::Refuse).unwrap();
    let sk = asset.skeleton().unwrap();
    assert_eq!(sk.joints().len(), 5, "four bones and the end");
}
