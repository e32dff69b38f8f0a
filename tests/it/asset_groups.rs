//! Constraints in asset terms: `{"group": …}` vertex sets naming OBJ `g`/`o`
//! groups and glTF nodes, meshes and primitives resolve to exactly the
//! welded vertices of their triangles (the expected sets are computed here
//! from the geometry, not from the group machinery); unknown names are
//! typed errors listing the asset's groups; `dend deform` poses by group.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

use dend::deform::{ConstraintsSpec, DeformError};
use dend::mesh::asset::groups::GroupKind;
use dend::mesh::asset::sample::{self, TubeOptions};
use dend::mesh::asset::Asset;
use dend::mesh::io::gltf::{self as g, Container, Sidecars};
use dend::mesh::io::Format;
use dend_testkit::assets::{banded_tube_obj, AROUND, RINGS};
use serde_json::{json, Value};

/// Welded vertices whose `z` is in `[lo, hi]`: the rings a band of the
/// banded tube touches.
fn rings_between(a: &Asset, lo: f64, hi: f64) -> BTreeSet<u32> {
    (0..a.mesh().num_vertices() as u32)
        .filter(|&v| (lo..=hi).contains(&a.mesh().positions()[v as usize][2]))
        .collect()
}

fn group_set(a: &Asset, group: Value) -> Result<BTreeSet<u32>, DeformError> {
    let r = serde_json::from_value(group).unwrap();
    a.group_vertices(&r).map(|v| v.into_iter().collect())
}

#[test]
fn obj_groups_resolve_to_the_welded_vertices_of_their_faces() {
    let obj = banded_tube_obj();
    let a = Asset::read_bytes(obj.as_bytes(), Format::Obj, Sidecars::Refuse).unwrap();
    // the seam column is welded: AROUND vertices per ring
    assert_eq!(a.mesh().num_vertices(), AROUND * RINGS);
    let top = (RINGS - 1) as f64;
    let base = rings_between(&a, 0.0, 1.0);
    let tip = rings_between(&a, top - 1.0, top);
    assert_eq!(base.len(), 2 * AROUND);
    assert_eq!(group_set(&a, json!("base")).unwrap(), base);
    assert_eq!(group_set(&a, json!("tip")).unwrap(), tip);
    assert_eq!(
        group_set(&a, json!("end")).unwrap(),
        tip,
        "second name on a g line"
    );
    assert_eq!(
        group_set(&a, json!("mid")).unwrap(),
        rings_between(&a, 1.0, top - 1.0),
        "shares its boundary rings with base and tip"
    );
    assert_eq!(
        group_set(&a, json!("tube")).unwrap().len(),
        AROUND * RINGS,
        "the o object holds every face"
    );
    // the listing: kinds, names and vertex counts
    let listed: Vec<(GroupKind, String, usize)> = a
        .groups()
        .into_iter()
        .map(|g| (g.kind, g.name.unwrap(), g.vertices))
        .collect();
    let want = [
        (GroupKind::O, "tube", AROUND * RINGS),
        (GroupKind::G, "base", 2 * AROUND),
        (GroupKind::G, "mid", (RINGS - 2) * AROUND),
        (GroupKind::G, "tip", 2 * AROUND),
        (GroupKind::G, "end", 2 * AROUND),
    ];
    assert_eq!(
        listed,
        want.map(|(k, n, v)| (k, n.to_owned(), v)).to_vec(),
        "{listed:?}"
    );
    // an unknown name: typed, naming it and listing what there is
    let e = group_set(&a, json!("LeftArm")).unwrap_err();
    let DeformError::UnknownGroup { group, available } = &e else {
        panic!("{e:?}")
    };
    assert_eq!(group, "\"LeftArm\"");
    assert!(
        available.contains(&"g \"base\"".to_owned()),
        "{available:?}"
    );
    assert!(e.to_string().contains("o \"tube\""), "{e}");
    // glTF-only selectors do not match OBJ groups
    assert!(group_set(&a, json!({"node": "base"})).is_err());
}

/// The skinned sample tube with its caps primitive moved to a second mesh
/// (`caps`) placed by a second node (`capsNode`, skinned like the first).
fn two_node_tube() -> Vec<u8> {
    let input = sample::tube(TubeOptions::default()).unwrap();
    let u = |at: usize| u32::from_le_bytes(input[at..at + 4].try_into().unwrap()) as usize;
    let jl = u(12);
    let mut doc: Value = serde_json::from_slice(&input[20..20 + jl]).unwrap();
    let bin = input[28 + jl..28 + jl + u(20 + jl)].to_vec();
    let caps = doc["meshes"][0]["primitives"][1].take();
    doc["meshes"][0]["primitives"] = json!([doc["meshes"][0]["primitives"][0]]);
    doc["meshes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "caps", "primitives": [caps]}));
    doc["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "capsNode", "mesh": 1, "skin": 0}));
    doc["scenes"][0]["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!(3));
    g::assemble(&serde_json::to_vec(&doc).unwrap(), bin, Container::Glb)
}

#[test]
fn gltf_nodes_meshes_and_primitives_resolve_to_their_vertices() {
    let (n, r) = (16, 13); // the sample's default
    let one = sample::tube(TubeOptions::default()).unwrap();
    let two = two_node_tube();
    for (bytes, caps) in [
        (&one, json!({"primitive": [0, 1]})),
        (&two, json!({"node": "capsNode"})),
        (&two, json!({"mesh": 1})),
        (&two, json!("caps")),
        (&two, json!({"primitive": ["caps", 0]})),
    ] {
        let a = Asset::read_bytes(bytes, Format::Glb, Sidecars::Refuse).unwrap();
        assert_eq!(
            a.mesh().num_vertices(),
            n * r + 2,
            "caps welded to the tube"
        );
        // skinned: mesh space, z in [0, 3]; the caps are the end rings and
        // the two centres, the tube everything but the centres
        let p = a.mesh().positions();
        let ends: BTreeSet<u32> = (0..p.len() as u32)
            .filter(|&v| p[v as usize][2] == 0.0 || p[v as usize][2] == 3.0)
            .collect();
        let side: BTreeSet<u32> = (0..p.len() as u32)
            .filter(|&v| p[v as usize][0] != 0.0 || p[v as usize][1] != 0.0)
            .collect();
        assert_eq!((ends.len(), side.len()), (2 * n + 2, n * r));
        assert_eq!(group_set(&a, caps.clone()).unwrap(), ends, "{caps}");
        assert_eq!(group_set(&a, json!({"primitive": [0, 0]})).unwrap(), side);
        // node 0 and mesh 0 ("tube") hold the caps too unless they moved out
        let whole = if bytes == &one {
            (0..p.len() as u32).collect()
        } else {
            side.clone()
        };
        assert_eq!(group_set(&a, json!({"node": 0})).unwrap(), whole, "{caps}");
        assert_eq!(
            group_set(&a, json!("tube")).unwrap(),
            whole,
            "node and mesh"
        );
    }
    let a = Asset::read_bytes(&two, Format::Glb, Sidecars::Refuse).unwrap();
    let names: Vec<String> = a.groups().iter().map(ToString::to_string).collect();
    assert_eq!(
        names,
        [
            format!("node 0 \"tube\" ({} vertices)", n * r),
            format!("node 3 \"capsNode\" ({} vertices)", 2 * n + 2),
            format!("mesh 0 \"tube\" ({} vertices)", n * r),
            format!("mesh 1 \"caps\" ({} vertices)", 2 * n + 2),
            format!("primitive [0, 0] ({} vertices)", n * r),
            format!("primitive [1, 0] ({} vertices)", 2 * n + 2),
        ]
    );
    for bad in [
        json!({"node": "arm"}),
        json!({"node": 1}),
        json!({"mesh": 2}),
        json!({"primitive": [0, 1]}),
        json!("hip"),
    ] {
        let e = group_set(&a, bad.clone()).unwrap_err();
        assert!(
            matches!(&e, DeformError::UnknownGroup { available, .. } if available.len() == 6),
            "{bad}: {e:?}"
        );
    }
}

#[test]
fn constraints_by_group_resolve_like_their_index_lists() {
    let obj = banded_tube_obj();
    let a = Asset::read_bytes(obj.as_bytes(), Format::Obj, Sidecars::Refuse).unwrap();
    let spec: ConstraintsSpec = serde_json::from_value(json!({
        "fixed": {"group": "base"},
        "handles": [{"name": "tip", "vertices": {"group": "tip"}, "translate": [1, 0, 0]}]
    }))
    .unwrap();
    // without the asset a group is an error, not an empty set
    assert!(matches!(
        spec.resolve(a.mesh()),
        Err(DeformError::UnknownGroup { ref available, .. }) if available.is_empty()
    ));
    let c = a.resolve_groups(&spec).unwrap().resolve(a.mesh()).unwrap();
    let top = (RINGS - 1) as f64;
    let want = |lo, hi| rings_between(&a, lo, hi).into_iter().collect::<Vec<_>>();
    assert_eq!(c.fixed, want(0.0, 1.0));
    assert_eq!(c.handles[0].vertices, want(top - 1.0, top));
    // groups that overlap are refused like overlapping index lists
    let spec: ConstraintsSpec = serde_json::from_value(json!({
        "fixed": {"group": "base"},
        "handles": [{"name": "mid", "vertices": {"group": "mid"}}]
    }))
    .unwrap();
    let e = a
        .resolve_groups(&spec)
        .unwrap()
        .resolve(a.mesh())
        .unwrap_err();
    assert!(matches!(e, DeformError::OverlappingSets { .. }), "{e:?}");
}

fn dend(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dend"))
        .args(args)
        .output()
        .unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn dend_deform_poses_an_obj_by_group_and_refuses_unknown_groups() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("tube.obj");
    let out = dir.path().join("posed.obj");
    let c = dir.path().join("c.json");
    std::fs::write(&input, banded_tube_obj()).unwrap();
    std::fs::write(
        &c,
        r#"{"fixed": {"group": "base"},
            "handles": [{"name": "tip", "vertices": {"group": "tip"}, "translate": [1.5, 0, 0]}]}"#,
    )
    .unwrap();
    let o = dend(&["deform", s(&input), "--constraints", s(&c), "-o", s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rest = Asset::read_path(&input).unwrap();
    let posed = Asset::read_path(&out).unwrap();
    assert_eq!(posed.positions().len(), rest.positions().len());
    let top = (RINGS - 1) as f64;
    let (p0, p1) = (rest.mesh().positions(), posed.mesh().positions());
    for v in rings_between(&rest, 0.0, 1.0) {
        assert!(dend_testkit::max_dist(&[p1[v as usize]], &[p0[v as usize]]) < 1e-9);
    }
    for v in rings_between(&rest, top - 1.0, top) {
        let want = [
            p0[v as usize][0] + 1.5,
            p0[v as usize][1],
            p0[v as usize][2],
        ];
        assert!(
            dend_testkit::max_dist(&[p1[v as usize]], &[want]) < 1e-6,
            "{v}"
        );
    }
    assert!(dend_testkit::max_dist(p1, p0) > 1.4);
    // the group list in `dend info`
    let o = dend(&["info", s(&input)]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains(&format!("g \"tip\" ({} vertices)", 2 * AROUND)),
        "{text}"
    );
    // an unknown group: exit 2, named, with the asset's groups listed
    std::fs::write(
        &c,
        r#"{"fixed": {"group": "base"}, "handles": [{"vertices": {"group": "arm"}}]}"#,
    )
    .unwrap();
    let o = dend(&["deform", s(&input), "--constraints", s(&c), "-o", s(&out)]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("unknown group \"arm\""), "{err}");
    assert!(
        err.contains("g \"base\"") && err.contains("o \"tube\""),
        "{err}"
    );
}

#[test]
fn dend_deform_poses_a_glb_by_node_and_the_result_validates() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("two.glb");
    let out = dir.path().join("posed.glb");
    let c = dir.path().join("c.json");
    let bytes = two_node_tube();
    std::fs::write(&input, &bytes).unwrap();
    // both caps held by naming their node, the middle ring (z = 1.5) pulled
    std::fs::write(
        &c,
        r#"{"fixed": {"group": {"node": "capsNode"}},
            "handles": [{"name": "mid", "vertices": {"box": {"min": [-9, -9, 1.4], "max": [9, 9, 1.6]}},
                         "translate": [0.3, 0, 0]}]}"#,
    )
    .unwrap();
    let o = dend(&["deform", s(&input), "--constraints", s(&c), "-o", s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rest = Asset::read_path(&input).unwrap();
    let posed = Asset::read_path(&out).unwrap();
    assert_eq!(posed.positions().len(), rest.positions().len());
    let (p0, p1) = (rest.mesh().positions(), posed.mesh().positions());
    let (mut held, mut pulled) = (0, 0);
    for v in 0..p0.len() {
        let z = p0[v][2];
        if z == 0.0 || z == 3.0 {
            assert_eq!(p1[v], p0[v], "cap vertex {v} kept its stored bits");
            held += 1;
        } else if z == 1.5 {
            let want = [p0[v][0] + 0.3, p0[v][1], z];
            assert!(dend_testkit::max_dist(&[p1[v]], &[want]) < 1e-6, "{v}");
            pulled += 1;
        }
    }
    assert_eq!((held, pulled), (2 * 16 + 2, 16));
    for (name, b) in [
        ("two.glb", bytes),
        ("posed.glb", std::fs::read(&out).unwrap()),
    ] {
        if let Some(r) = dend_testkit::gltf_validator::validate(&b, name) {
            assert_eq!((r.errors, r.warnings), (0, 0), "{name}: {}", r.messages);
        }
    }
}
