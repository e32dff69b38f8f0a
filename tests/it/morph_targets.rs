//! Poses exported as glTF morph targets (`GET …/export?format=glb&as=morph-targets`)
//! on the generated textured skinned tube (and its node-transformed
//! variant) and on a shared character: the Khronos validator finds no
//! error and no warning the input did not have; every accessor, skin,
//! node, material and animation of the input is kept byte for byte; each
//! target's base position plus its delta, read with the `gltf` crate,
//! equals the saved pose as the posed export writes it, to 1e-5; names,
//! weights and the animation through the poses are there.

use std::time::Duration;

use dend::mesh::asset::sample::{self, TubeOptions};
use dend::mesh::asset::Asset;
use dend::mesh::io::gltf::{Container, Sidecars};
use dend::mesh::io::Format;
use dend_client::ws::DeltaJson;
use dend_client::{
    Client, ClientError, ConstraintsSpec, HandleSpec, SavePose, SessionClient, SessionParams,
    VertexSet,
};
use dend_server::Config;
use dend_testkit::server::start;
use serde_json::{json, Value};

/// The JSON chunk and BIN chunk of a GLB (an independent split).
fn glb_parts(bytes: &[u8]) -> (Value, Vec<u8>) {
    let u = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let jl = u(12);
    let json = serde_json::from_slice(&bytes[20..20 + jl]).unwrap();
    let bl = u(20 + jl);
    (json, bytes[28 + jl..28 + jl + bl].to_vec())
}

fn document(json: &Value) -> gltf::Document {
    gltf::Document::from_json(serde_json::from_value(json.clone()).unwrap()).unwrap()
}

/// The element bytes of accessor `a` (stride gaps skipped).
fn accessor_bytes(a: &gltf::Accessor<'_>, bin: &[u8]) -> Vec<u8> {
    let v = a.view().unwrap();
    let elem = a.size();
    let stride = v.stride().unwrap_or(elem);
    let start = v.offset() + a.offset();
    (0..a.count())
        .flat_map(|k| bin[start + k * stride..start + k * stride + elem].to_vec())
        .collect()
}

fn vec3s(a: &gltf::Accessor<'_>, bin: &[u8]) -> Vec<[f32; 3]> {
    accessor_bytes(a, bin)
        .chunks(12)
        .map(|c| {
            std::array::from_fn(|k| f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap()))
        })
        .collect()
}

fn scalars(a: &gltf::Accessor<'_>, bin: &[u8]) -> Vec<f32> {
    accessor_bytes(a, bin)
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

/// Checks `out`, the morph-target export of `input` with `poses` (name,
/// welded pose) in order, with `animation`.
fn check_morph_export(
    input: &[u8],
    out: &[u8],
    poses: &[(String, Vec<[f64; 3]>)],
    animation: bool,
) {
    let (j0, b0) = glb_parts(input);
    let (j1, b1) = glb_parts(out);
    let (d0, d1) = (document(&j0), document(&j1));
    // the rest data: every input accessor's bytes, and the input's own
    // objects, unchanged
    assert!(
        b1.len() > b0.len() && b1[..b0.len()] == b0[..],
        "the input's buffer comes first, unchanged"
    );
    for a in d0.accessors() {
        let b = d1.accessors().nth(a.index()).unwrap();
        assert_eq!(
            accessor_bytes(&a, &b0),
            accessor_bytes(&b, &b1),
            "accessor {}",
            a.index()
        );
        assert_eq!(j0["accessors"][a.index()], j1["accessors"][a.index()]);
    }
    for key in [
        "materials",
        "skins",
        "nodes",
        "scenes",
        "textures",
        "images",
        "samplers",
    ] {
        assert_eq!(j0[key], j1[key], "{key}");
    }
    let had_animations = j0["animations"].as_array().map_or(0, Vec::len);
    for i in 0..had_animations {
        assert_eq!(j0["animations"][i], j1["animations"][i]);
    }
    // the poses as the posed export writes them (POSITION in local space)
    let asset = Asset::read_bytes(input, Format::Glb, Sidecars::Refuse).unwrap();
    let posed: Vec<(Value, Vec<u8>)> = poses
        .iter()
        .map(|(_, p)| glb_parts(&asset.export(p, Format::Glb).unwrap()))
        .collect();
    let names: Vec<&str> = poses.iter().map(|(n, _)| n.as_str()).collect();
    let mut worst = 0.0f32;
    for mesh in d1.meshes() {
        let mj = &j1["meshes"][mesh.index()];
        assert_eq!(
            mj["extras"]["targetNames"],
            json!(names),
            "mesh {}",
            mesh.index()
        );
        assert_eq!(mj["weights"], json!(vec![0.0; poses.len()]));
        for prim in mesh.primitives() {
            let targets: Vec<_> = prim.morph_targets().collect();
            assert_eq!(targets.len(), poses.len());
            let base_acc = prim.get(&gltf::Semantic::Positions).unwrap();
            let base = vec3s(&base_acc, &b1);
            for (t, (pj, pb)) in targets.iter().zip(&posed) {
                let delta_acc = t.positions().expect("a POSITION delta");
                let delta = vec3s(&delta_acc, &b1);
                let want = vec3s(&document(pj).accessors().nth(base_acc.index()).unwrap(), pb);
                assert_eq!((delta.len(), want.len()), (base.len(), base.len()));
                for ((b, d), w) in base.iter().zip(&delta).zip(&want) {
                    for k in 0..3 {
                        worst = worst.max((b[k] + d[k] - w[k]).abs());
                    }
                }
                // accessor min/max are the deltas' bounds
                let (lo, hi) = (delta_acc.min().unwrap(), delta_acc.max().unwrap());
                for k in 0..3 {
                    let min = delta.iter().map(|d| d[k]).fold(f32::INFINITY, f32::min);
                    let max = delta.iter().map(|d| d[k]).fold(f32::NEG_INFINITY, f32::max);
                    // as the f32 the validator compares (JSON parsers differ in
                    // the last f64 bit)
                    assert_eq!(lo[k].as_f64().unwrap() as f32, min);
                    assert_eq!(hi[k].as_f64().unwrap() as f32, max);
                }
                assert_eq!(
                    t.normals().is_some(),
                    prim.get(&gltf::Semantic::Normals).is_some(),
                    "NORMAL deltas where the primitive has normals"
                );
            }
        }
    }
    assert!(worst <= 1e-5, "base + delta vs the pose: {worst}");
    let animations = j1["animations"].as_array().map_or(0, Vec::len);
    if animation {
        assert_eq!(animations, had_animations + 1);
        let a = d1.animations().last().unwrap();
        assert_eq!(a.name(), Some("poses"));
        for ch in a.channels() {
            assert_eq!(
                ch.target().property(),
                gltf::animation::Property::MorphTargetWeights
            );
            let input = scalars(&ch.sampler().input(), &b1);
            assert_eq!(
                input,
                (0..=poses.len()).map(|i| i as f32).collect::<Vec<_>>()
            );
            let w = scalars(&ch.sampler().output(), &b1);
            let n = poses.len();
            for (k, row) in w.chunks(n).enumerate() {
                let want: Vec<f32> = (0..n).map(|i| if k == i + 1 { 1.0 } else { 0.0 }).collect();
                assert_eq!(row, want, "key {k}");
            }
        }
    } else {
        assert_eq!(animations, had_animations);
    }
    // the validator: nothing the input did not already have
    let (Some(r0), Some(r1)) = (
        dend_testkit::gltf_validator::validate(input, "input.glb"),
        dend_testkit::gltf_validator::validate(out, "morph.glb"),
    ) else {
        return;
    };
    assert_eq!(r1.errors, 0, "{}", r1.messages);
    assert!(r1.warnings <= r0.warnings, "{}", r1.messages);
}

/// Uploads `input`, sets `spec`, applies each `(name, drag)` and saves the
/// settled pose under its name; returns the session and the named poses.
async fn pose_and_save(
    base: &str,
    input: Vec<u8>,
    spec: ConstraintsSpec,
    drags: &[(&str, DeltaJson)],
) -> Result<(SessionClient, Vec<(String, Vec<[f64; 3]>)>), ClientError> {
    let c = Client::new(base);
    let mesh = c.upload_file(input, "glb").await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    s.set_constraints(&spec).await?;
    s.wait_ready(Duration::from_secs(120)).await?;
    let http = reqwest::Client::new();
    let url = |tail: &str| format!("{base}/v1/sessions/{}{tail}", s.id);
    let mut poses = vec![];
    for (name, drag) in drags {
        s.drag("top", drag.clone(), Some(40)).await?;
        let save = SavePose {
            name: name.to_string(),
            replace: false,
        };
        let r = http
            .post(url("/poses"))
            .bearer_auth(&s.token)
            .json(&save)
            .send()
            .await?;
        assert_eq!(r.status(), 201);
        let got: Value = http
            .get(url(&format!("/poses/{name}")))
            .bearer_auth(&s.token)
            .send()
            .await?
            .json()
            .await?;
        let p: Vec<[f64; 3]> = serde_json::from_value(got["positions"].clone()).unwrap();
        poses.push((name.to_string(), p));
    }
    Ok((s, poses))
}

async fn export(s: &SessionClient, base: &str, query: &str) -> reqwest::Response {
    reqwest::Client::new()
        .get(format!("{base}/v1/sessions/{}/export?{query}", s.id))
        .bearer_auth(&s.token)
        .send()
        .await
        .unwrap()
}

fn tube_spec() -> ConstraintsSpec {
    ConstraintsSpec::new(
        VertexSet::bbox([-9.0, -9.0, -0.01], [9.0, 9.0, 0.3]),
        vec![HandleSpec::named(
            "top",
            VertexSet::bbox([-9.0, -9.0, 2.7], [9.0, 9.0, 3.1]),
        )],
    )
}

#[tokio::test]
async fn the_sample_tube_round_trips_as_morph_targets() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    for skinned in [true, false] {
        let input = sample::tube(TubeOptions {
            skinned,
            ..TubeOptions::default()
        })
        .unwrap();
        let drags = [
            ("twist", DeltaJson::axis_angle([0.0, 0.0, 1.0], 60.0)),
            ("lean", DeltaJson::translate([0.6, 0.0, -0.2])),
        ];
        let (s, poses) = pose_and_save(&base, input.clone(), tube_spec(), &drags).await?;
        for animation in [false, true] {
            let q = format!(
                "format=glb&as=morph-targets&animation={}",
                u8::from(animation)
            );
            let r = export(&s, &base, &q).await;
            assert_eq!(r.status(), 200);
            assert_eq!(r.headers()["content-type"], "model/gltf-binary");
            let out = r.bytes().await?.to_vec();
            check_morph_export(&input, &out, &poses, animation);
        }
        // the poses differ from rest and from each other
        assert!(dend_testkit::max_dist(&poses[0].1, &poses[1].1) > 0.1);
    }
    Ok(())
}

#[tokio::test]
async fn without_saved_poses_the_current_pose_is_the_one_target() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let input = sample::tube(TubeOptions::default()).unwrap();
    let (s, _) = pose_and_save(&base, input.clone(), tube_spec(), &[]).await?;
    let p = s
        .drag("top", DeltaJson::translate([0.3, 0.2, 0.0]), Some(40))
        .await?;
    let out = export(&s, &base, "format=glb&as=morph-targets")
        .await
        .bytes()
        .await?;
    check_morph_export(&input, &out, &[("pose".into(), p.positions)], false);
    // a .gltf container of the same
    let r = export(&s, &base, "format=gltf&as=morph-targets").await;
    assert_eq!(r.headers()["content-type"], "model/gltf+json");
    let j: Value = r.json().await?;
    assert_eq!(j["meshes"][0]["extras"]["targetNames"], json!(["pose"]));
    // typed errors: an unknown `as`, a non-glTF format, a mesh without a glTF file
    for q in ["format=glb&as=blend", "format=obj&as=morph-targets"] {
        let r = export(&s, &base, q).await;
        assert_eq!(r.status(), 422, "{q}");
        let e: Value = r.json().await?;
        assert_eq!(e["code"], "unsupported_export", "{q}");
    }
    let c = Client::new(&base);
    let (pts, tris) = dend_testkit::server::grid(4);
    let m = c.upload_json(&pts, &tris).await?;
    let plain = c.create_session(&m.id, SessionParams::default()).await?;
    let r = export(&plain, &base, "format=glb&as=morph-targets").await;
    assert_eq!(r.status(), 422);
    Ok(())
}

#[tokio::test]
async fn a_shared_character_round_trips_as_morph_targets() -> Result<(), ClientError> {
    let Some(mesh) = dend_testkit::shared_mesh("hand_1502.obj") else {
        return Ok(()); // skip recorded by the testkit
    };
    let input =
        dend::mesh::io::gltf::write_mesh(mesh.positions(), mesh.triangles(), Container::Glb);
    let (lo, hi) = bounds(mesh.positions());
    let x = |f: f64| lo[0] + f * (hi[0] - lo[0]);
    let spec = ConstraintsSpec::new(
        VertexSet::bbox(
            [lo[0] - 1.0, lo[1] - 1.0, lo[2] - 1.0],
            [x(0.15), hi[1] + 1.0, hi[2] + 1.0],
        ),
        vec![HandleSpec::named(
            "top",
            VertexSet::bbox(
                [x(0.85), lo[1] - 1.0, lo[2] - 1.0],
                [hi[0] + 1.0, hi[1] + 1.0, hi[2] + 1.0],
            ),
        )],
    );
    let size = hi[0] - lo[0];
    let drags = [
        ("up", DeltaJson::translate([0.0, 0.15 * size, 0.0])),
        ("curl", DeltaJson::axis_angle([0.0, 0.0, 1.0], 25.0)),
    ];
    let (base, _state) = start(Config::default()).await;
    let (s, poses) = pose_and_save(&base, input.clone(), spec, &drags).await?;
    let out = export(&s, &base, "format=glb&as=morph-targets&animation=1")
        .await
        .bytes()
        .await?;
    check_morph_export(&input, &out, &poses, true);
    Ok(())
}

fn bounds(p: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for q in p {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    (lo, hi)
}
