//! glTF/GLB through the `dend` command line: `deform asset.glb -o posed.glb`
//! keeps the asset's vertex count, UVs and skin and passes the Khronos
//! validator; `gen`, `info`, `curvature` read and write glTF; malformed glTF
//! exits with 2.

use std::path::Path;
use std::process::Command;

use dend::mesh::asset::sample::{self, TubeOptions};
use dend::mesh::asset::Asset;
use dend::mesh::io::gltf::{Container, GltfAsset, Sidecars};
use dend::mesh::io::Format;

fn dend(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dend"))
        .args(args)
        .output()
        .unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

const TWIST: &str = r#"{
  "fixed": {"box": {"min": [-9, -9, -0.01], "max": [9, 9, 0.3]}},
  "handles": [{"name": "top", "vertices": {"box": {"min": [-9, -9, 2.7], "max": [9, 9, 3.1]}},
               "rotate": {"axis": [0, 0, 1], "degrees": 90}}]
}"#;

#[test]
fn deform_glb_keeps_vertex_count_uvs_and_skin_and_validates() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("tube.glb");
    let posed = dir.path().join("posed.glb");
    let posed_gltf = dir.path().join("posed.gltf");
    let c = dir.path().join("c.json");
    let bytes = sample::tube(TubeOptions::default()).unwrap();
    std::fs::write(&input, &bytes).unwrap();
    std::fs::write(&c, TWIST).unwrap();
    for out in [&posed, &posed_gltf] {
        let o = dend(&["deform", s(&input), "--constraints", s(&c), "-o", s(out)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let rest = GltfAsset::parse(&bytes, Sidecars::Refuse).unwrap();
    for out in [&posed, &posed_gltf] {
        let got = std::fs::read(out).unwrap();
        let a = GltfAsset::parse(&got, Sidecars::Refuse).unwrap();
        assert_eq!(a.positions().len(), rest.positions().len());
        assert_eq!(a.triangles(), rest.triangles());
        assert_eq!(a.summary(), rest.summary(), "attributes, skin, materials");
        assert!(
            dend_testkit::max_dist(a.positions(), rest.positions()) > 0.3,
            "posed"
        );
        if let Some(r) =
            dend_testkit::gltf_validator::validate(&got, out.file_name().unwrap().to_str().unwrap())
        {
            assert_eq!((r.errors, r.warnings), (0, 0), "{}", r.messages);
        }
    }
    // dend info reports both vertex counts and the attributes
    let o = dend(&["info", "--json", s(&posed)]);
    assert!(o.status.success());
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(info["asset"]["asset_vertices"], 17 * 15);
    assert_eq!(info["asset"]["welded_vertices"], 16 * 13 + 2);
    assert_eq!(info["vertices"], 16 * 13 + 2);
    let attrs = info["asset"]["attributes"].to_string();
    for a in ["TEXCOORD_0", "JOINTS_0", "WEIGHTS_0", "skins: 1"] {
        assert!(attrs.contains(a), "{attrs}");
    }
}

#[test]
fn the_generated_assets_and_gen_outputs_pass_the_validator() {
    let mut files = Vec::new();
    for skinned in [true, false] {
        for container in [Container::Glb, Container::Json] {
            let o = TubeOptions {
                skinned,
                container,
                ..TubeOptions::default()
            };
            let ext = if container == Container::Glb {
                "glb"
            } else {
                "gltf"
            };
            files.push((format!("tube-{skinned}.{ext}"), sample::tube(o).unwrap()));
        }
    }
    let dir = tempfile::tempdir().unwrap();
    for ext in ["glb", "gltf"] {
        let p = dir.path().join(format!("torus.{ext}"));
        let o = dend(&["gen", "torus", "-o", s(&p)]);
        assert!(o.status.success());
        files.push((format!("torus.{ext}"), std::fs::read(&p).unwrap()));
    }
    // an unskinned asset under transformed nodes, bent by a translation
    let a = Asset::read_bytes(&files[2].1, Format::Glb, Sidecars::Refuse).unwrap();
    let pose: Vec<_> = a
        .mesh()
        .positions()
        .iter()
        .map(|p| [p[0], p[1] + 0.1 * p[0] * p[0], p[2]])
        .collect();
    files.push(("bent.glb".into(), a.export(&pose, Format::Glb).unwrap()));
    for (name, bytes) in files {
        match dend_testkit::gltf_validator::validate(&bytes, &name) {
            Some(r) => assert_eq!((r.errors, r.warnings), (0, 0), "{name}: {}", r.messages),
            None => return,
        }
    }
}

#[test]
fn gen_info_curvature_read_and_write_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("bar.glb");
    assert!(dend(&["gen", "bar", "-o", s(&glb)]).status.success());
    let csv = dir.path().join("k.csv");
    let o = dend(&["curvature", s(&glb), "-o", s(&csv)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read_to_string(&csv).unwrap().lines().count(),
        856 + 1
    );
    let o = dend(&["info", s(&glb)]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("856 vertices in the file's layout, 856 welded"),
        "{text}"
    );
}

#[test]
fn malformed_gltf_exits_with_2() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.glb");
    let mut bytes = sample::tube(TubeOptions::default()).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&bad, &bytes).unwrap();
    for args in [
        vec!["info", s(&bad)],
        vec!["deform", s(&bad), "--constraints", s(&bad), "-o", "x.glb"],
    ] {
        let o = dend(&args);
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("GLB"), "{err}");
    }
}
