//! The rig on generated limbs: skeleton and regions, the fit against poses
//! made by skinning with known joint rotations, the corrective, errors.

use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};

use super::sample::{limb, LimbOptions};
use super::*;
use crate::mesh::asset::groups::NameOrIndex;
use crate::mesh::asset::sample::{tube, TubeOptions};
use crate::mesh::asset::Asset;
use crate::mesh::io::gltf::{Container, Sidecars};
use crate::mesh::io::Format;
use crate::mesh::selection::JointSel;
use crate::mesh::Point;

fn read(bytes: &[u8], format: Format) -> Asset {
    Asset::read_bytes(bytes, format, Sidecars::Refuse).unwrap()
}

fn limb_asset(o: LimbOptions) -> Asset {
    let format = match o.container {
        Container::Glb => Format::Glb,
        Container::Json => Format::Gltf,
    };
    read(&limb(o), format)
}

fn sel(name: &str, with_children: bool) -> JointSel {
    JointSel {
        joint: NameOrIndex::Name(name.into()),
        with_children,
    }
}

fn degrees(r: &Matrix3<f64>) -> f64 {
    ((r.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// The welded pose skinning gives when joint `k` (and so its subtree) is
/// turned by `rot` about its head, the rest at rest: computed directly
/// from the weights, independently of the fit's model.
fn skinned_turn(asset: &Asset, sk: &Skeleton, k: usize, rot: &Matrix3<f64>) -> Vec<Point> {
    let in_subtree = |mut j: usize| loop {
        if j == k {
            return true;
        }
        match sk.joints()[j].parent {
            Some(p) => j = p,
            None => return false,
        }
    };
    let h = sk.joints()[k].head;
    let mut welded = vec![[0.0; 3]; asset.mesh().num_vertices()];
    for (a, v) in asset.positions().iter().enumerate() {
        let v = Vector3::from(*v);
        let turned = rot * (v - h) + h;
        let p: Vector3<f64> = sk.influences()[a]
            .iter()
            .map(|&(j, w)| {
                if in_subtree(j as usize) {
                    turned * w
                } else {
                    v * w
                }
            })
            .sum();
        welded[asset.to_welded()[a] as usize] = [p.x, p.y, p.z];
    }
    welded
}

/// The local rotation each joint's written TRS adds to its rest one.
fn local_turns(sk: &Skeleton, pose: &RigPose) -> Vec<Matrix3<f64>> {
    pose.joints
        .iter()
        .zip(&sk.skin().joints)
        .map(|(t, j)| {
            let [x, y, z, w] = t.rotation.map(f64::from);
            let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
            (j.rest.rotation.inverse() * q)
                .to_rotation_matrix()
                .into_inner()
        })
        .collect()
}

#[test]
fn the_limb_lists_its_chain_and_regions() {
    let asset = limb_asset(LimbOptions::default());
    let sk = asset.skeleton().unwrap();
    let info = sk.info();
    let names: Vec<&str> = info.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["bone0", "bone1", "bone2", "end"]);
    let parents: Vec<Option<&str>> = info.joints.iter().map(|j| j.parent.as_deref()).collect();
    assert_eq!(parents, [None, Some("bone0"), Some("bone1"), Some("bone2")]);
    for (k, j) in info.joints.iter().enumerate() {
        assert!((j.head[1] - k as f64).abs() < 1e-6, "{j:?}");
    }
    // every referenced welded vertex is in exactly one region; `end` has none
    let regions: Vec<Vec<u32>> = (0..4)
        .map(|k| {
            sk.joint_vertices(&JointSel {
                joint: NameOrIndex::Index(k),
                with_children: false,
            })
            .unwrap()
        })
        .collect();
    assert!(regions[3].is_empty());
    // the listing's regions are the selectors'
    for (k, r) in regions.iter().enumerate() {
        assert_eq!(&info.joints[k].region, r, "bone{k}");
    }
    let total: usize = regions.iter().map(Vec::len).sum();
    assert_eq!(total, asset.mesh().num_vertices());
    for (k, r) in regions.iter().enumerate().take(3) {
        assert_eq!(info.joints[k].vertices, r.len());
        // the region of bone k lies along [k, k + 1] (its dominant span)
        for &v in r {
            let y = asset.mesh().positions()[v as usize][1];
            assert!(y >= k as f64 - 0.31 && y <= k as f64 + 1.31, "bone{k}: {y}");
        }
    }
    let with = sk.joint_vertices(&sel("bone1", true)).unwrap();
    let mut union = [regions[1].clone(), regions[2].clone()].concat();
    union.sort_unstable();
    assert_eq!(with, union);
    let RigError::UnknownJoint { joint, available } =
        sk.joint_vertices(&sel("hand.L", false)).unwrap_err()
    else {
        panic!("not an unknown joint");
    };
    assert_eq!(joint, "\"hand.L\"");
    assert_eq!(available, ["bone0", "bone1", "bone2", "end"]);
}

#[test]
fn a_turned_joint_is_recovered_and_the_others_stay_at_rest() {
    for (bones, k, axis, deg) in [
        (3, 1, Vector3::z(), 40.0),
        (3, 2, Vector3::new(1.0, 0.0, 1.0), -75.0),
        (4, 1, Vector3::new(0.3, 1.0, -0.5), 120.0),
        (5, 3, Vector3::x(), 25.0),
    ] {
        let asset = limb_asset(LimbOptions {
            bones,
            offset: [0.5, -1.0, 2.0],
            ..LimbOptions::default()
        });
        let sk = asset.skeleton().unwrap();
        let rot = Rotation3::from_axis_angle(&Unit::new_normalize(axis), f64::to_radians(deg))
            .into_inner();
        let pose = skinned_turn(&asset, &sk, k, &rot);
        let fitted = fit(&asset, &sk, &pose, &FitOptions::default()).unwrap();
        let turns = local_turns(&sk, &fitted);
        for (j, t) in turns.iter().enumerate() {
            let off = if j == k {
                degrees(&(rot.transpose() * t))
            } else {
                degrees(t)
            };
            let limit = if j == k { 1.0 } else { 0.1 };
            assert!(
                off < limit,
                "{bones} bones, joint {k} turned: joint {j} is {off}° off"
            );
        }
        assert!(fitted.residual.max < 1e-3, "{:?}", fitted.residual);
        assert!(fitted.residual.mean <= fitted.residual.max);
    }
}

#[test]
fn the_corrective_makes_skinning_give_the_pose() {
    // a pose no skinning gives: the limb bent and bulged
    let asset = limb_asset(LimbOptions::default());
    let sk = asset.skeleton().unwrap();
    let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.6).into_inner();
    let mut pose = skinned_turn(&asset, &sk, 1, &rot);
    for p in &mut pose {
        let bulge = 0.05 * (3.0 * p[1]).sin();
        *p = [
            p[0] * (1.0 + bulge),
            p[1] + 0.02 * p[0],
            p[2] * (1.0 - bulge),
        ];
    }
    let fitted = fit(&asset, &sk, &pose, &FitOptions::default()).unwrap();
    assert!(fitted.residual.max > 1e-3, "the bulge is not skinning");
    let asset_pose = asset.asset_pose(&pose).unwrap();
    let mut worst = 0.0f64;
    for (i, v) in asset.positions().iter().enumerate() {
        let d = fitted.corrective[i];
        let x = Vector3::new(v[0] + d[0], v[1] + d[1], v[2] + d[2]).push(1.0);
        let drawn: Vector3<f64> = sk.influences()[i]
            .iter()
            .map(|&(j, w)| (fitted.skinning[j as usize] * x).xyz() * w)
            .sum();
        worst = worst.max((drawn - Vector3::from(asset_pose[i])).norm());
    }
    assert!(
        worst < 1e-12,
        "skinned + corrective is {worst} from the pose"
    );
}

#[test]
fn the_rest_pose_keeps_every_rest_transform() {
    let asset = limb_asset(LimbOptions::default());
    let sk = asset.skeleton().unwrap();
    let fitted = fit(
        &asset,
        &sk,
        asset.mesh().positions(),
        &FitOptions::default(),
    )
    .unwrap();
    for (t, j) in fitted.joints.iter().zip(&sk.skin().joints) {
        let c = j.rest.rotation.coords;
        assert_eq!(t.rotation, [c.x, c.y, c.z, c.w].map(|x| x as f32));
        let rt = j.rest.translation;
        assert_eq!(t.translation, [rt.x as f32, rt.y as f32, rt.z as f32]);
    }
    assert!(fitted.residual.max < 1e-12);
    assert!(fitted.corrective.iter().flatten().all(|d| d.abs() < 1e-12));
}

#[test]
fn a_moved_limb_moves_its_root_and_only_its_root() {
    let asset = limb_asset(LimbOptions::default());
    let sk = asset.skeleton().unwrap();
    let rot = Rotation3::from_axis_angle(&Vector3::x_axis(), 0.5).into_inner();
    let shift = Vector3::new(1.0, 2.0, -0.5);
    let pose: Vec<Point> = asset
        .mesh()
        .positions()
        .iter()
        .map(|p| {
            let q = rot * Vector3::from(*p) + shift;
            [q.x, q.y, q.z]
        })
        .collect();
    let fitted = fit(&asset, &sk, &pose, &FitOptions::default()).unwrap();
    let turns = local_turns(&sk, &fitted);
    assert!(degrees(&(rot.transpose() * turns[0])) < 1e-3);
    assert!(turns[1..].iter().all(|t| degrees(t) < 1e-3));
    let t = fitted.joints[0].translation;
    assert!(
        (Vector3::from(t.map(f64::from)) - shift).norm() < 1e-5,
        "{t:?}"
    );
    assert!(fitted.residual.max < 1e-6);
}

#[test]
fn weights_are_normalised_and_counted() {
    let asset = limb_asset(LimbOptions::default());
    assert_eq!(asset.skeleton().unwrap().info().renormalised_vertices, 0);
    // scale every weight by 0.8: each vertex is normalised back
    let g = limb(LimbOptions {
        container: Container::Json,
        ..LimbOptions::default()
    });
    let mut doc: serde_json::Value = serde_json::from_slice(&g).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_owned();
    let (head, data) = uri.split_once(',').unwrap();
    use base64::Engine as _;
    let mut bytes = base64::engine::general_purpose::STANDARD
        .decode(data)
        .unwrap();
    let view = doc["accessors"][3]["bufferView"].as_u64().unwrap() as usize;
    let start = doc["bufferViews"][view]["byteOffset"].as_u64().unwrap() as usize;
    let len = doc["bufferViews"][view]["byteLength"].as_u64().unwrap() as usize;
    for c in bytes[start..start + len].chunks_exact_mut(4) {
        let w = f32::from_le_bytes([c[0], c[1], c[2], c[3]]) * 0.8;
        c.copy_from_slice(&w.to_le_bytes());
    }
    let data = base64::engine::general_purpose::STANDARD.encode(&bytes);
    doc["buffers"][0]["uri"] = serde_json::json!(format!("{head},{data}"));
    let scaled = read(&serde_json::to_vec(&doc).unwrap(), Format::Gltf);
    let sk = scaled.skeleton().unwrap();
    assert_eq!(sk.info().renormalised_vertices, asset.positions().len());
    for inf in sk.influences() {
        assert!((inf.iter().map(|e| e.1).sum::<f64>() - 1.0).abs() < 1e-12);
    }
}

/// The limb as `.gltf` JSON, edited by `edit`.
fn edited_doc(edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let g = limb(LimbOptions {
        container: Container::Json,
        ..LimbOptions::default()
    });
    let mut doc: serde_json::Value = serde_json::from_slice(&g).unwrap();
    edit(&mut doc);
    serde_json::to_vec(&doc).unwrap()
}

/// The limb as `.gltf` JSON, edited by `edit`, read back.
fn edited(edit: impl FnOnce(&mut serde_json::Value)) -> Result<Skeleton, RigError> {
    read(&edited_doc(edit), Format::Gltf).skeleton()
}

#[test]
fn broken_or_missing_skins_are_typed_errors() {
    use crate::mesh::io::gltf::SkinError;
    let unskinned = tube(TubeOptions {
        skinned: false,
        ..TubeOptions::default()
    })
    .unwrap();
    assert_eq!(
        read(&unskinned, Format::Glb).skeleton().unwrap_err(),
        RigError::Skin(SkinError::NotSkinned)
    );
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    assert!(matches!(
        read(obj.as_bytes(), Format::Obj).skeleton(),
        Err(RigError::NotGltf {
            format: Format::Obj
        })
    ));
    // the skin lists two joints (and two bind matrices): vertices name a third
    let e = edited(|d| {
        d["skins"][0]["joints"] = serde_json::json!([2, 3]);
        d["accessors"][5]["count"] = serde_json::json!(2);
    });
    assert!(
        matches!(
            e,
            Err(RigError::Skin(SkinError::JointOutOfRange {
                joint: 2,
                joints: 2,
                ..
            }))
        ),
        "{e:?}"
    );
    // bind matrices for fewer joints than the skin has
    let e = edited(|d| d["accessors"][5]["count"] = serde_json::json!(3));
    assert!(
        matches!(e, Err(RigError::Skin(SkinError::BadSkin { .. }))),
        "{e:?}"
    );
    // joints without weights
    let e = edited(|d| {
        d["meshes"][0]["primitives"][0]["attributes"]
            .as_object_mut()
            .unwrap()
            .remove("WEIGHTS_0");
    });
    assert!(
        matches!(e, Err(RigError::Skin(SkinError::BadAttributes { .. }))),
        "{e:?}"
    );
    // a second mesh (its own accessors over the same data) under a second
    // skin: two rigs
    let two = |skinned: bool| {
        edited_doc(|d| {
            let accs = d["accessors"].as_array_mut().unwrap();
            let first = accs.len();
            let copies: Vec<_> = accs[..5].to_vec();
            accs.extend(copies);
            let mut skin2 = d["skins"][0].clone();
            skin2["joints"] = serde_json::json!([2, 3, 4, 5]);
            d["skins"].as_array_mut().unwrap().push(skin2);
            let attrs = serde_json::json!({"POSITION": first, "NORMAL": first + 1,
                "JOINTS_0": first + 2, "WEIGHTS_0": first + 3});
            let mesh =
                serde_json::json!({"primitives": [{"attributes": attrs, "indices": first + 4}]});
            d["meshes"].as_array_mut().unwrap().push(mesh);
            // (moved aside, so the two surfaces do not weld together)
            let mut node = serde_json::json!({"mesh": 1, "translation": [5.0, 0.0, 0.0]});
            if skinned {
                node["skin"] = serde_json::json!(1);
            }
            d["nodes"].as_array_mut().unwrap().push(node);
            let n = d["nodes"].as_array().unwrap().len() - 1;
            d["scenes"][0]["nodes"]
                .as_array_mut()
                .unwrap()
                .push(serde_json::json!(n));
        })
    };
    // (two skinned copies lie on each other in bind space, so the skin is
    // read from the document, before the surfaces are welded)
    let doc = crate::mesh::io::gltf::GltfAsset::parse(&two(true), Sidecars::Refuse).unwrap();
    assert_eq!(
        doc.skin().unwrap_err(),
        SkinError::SeveralSkins {
            skins: 2,
            unskinned: 0
        }
    );
    assert_eq!(
        read(&two(false), Format::Gltf).skeleton().unwrap_err(),
        RigError::Skin(SkinError::SeveralSkins {
            skins: 1,
            unskinned: 1
        })
    );
}

#[test]
fn the_skinned_sample_tube_recovers_its_tip() {
    // the sample tube's two joints (hip, tip) and its z-blended weights
    let asset = read(&tube(TubeOptions::default()).unwrap(), Format::Glb);
    let sk = asset.skeleton().unwrap();
    assert_eq!(sk.info().joints.len(), 2);
    let rot = Rotation3::from_axis_angle(&Vector3::y_axis(), 0.4).into_inner();
    let pose = skinned_turn(&asset, &sk, 1, &rot);
    let fitted = fit(&asset, &sk, &pose, &FitOptions::default()).unwrap();
    let turns = local_turns(&sk, &fitted);
    assert!(degrees(&(rot.transpose() * turns[1])) < 1.0);
    assert!(degrees(&turns[0]) < 0.1);
    assert!(fitted.residual.max < 1e-3);
}
