//! Fuzz-style property tests run in CI: random bytes and mutated valid files
//! never make a reader panic (they parse or return an error).

use dend::mesh::asset::sample::{self, TubeOptions};
use dend::mesh::asset::Asset;
use dend::mesh::gen::{generate, Shape, ShapeSpec};
use dend::mesh::io::gltf::{Container, Sidecars};
use dend::mesh::io::survey::{parse_def, parse_sel};
use dend::mesh::io::{parse_bytes, to_bytes_with, Encoding, Format};
use proptest::prelude::*;

fn seeds() -> Vec<(Format, Vec<u8>)> {
    let mut s = ShapeSpec::default_for(Shape::Torus);
    s.params.nu = Some(4);
    s.params.nv = Some(3);
    let m = generate(&s).unwrap();
    let mut out = Vec::new();
    for f in Format::ALL {
        for enc in [
            Encoding::Ascii,
            Encoding::BinaryLittleEndian,
            Encoding::BinaryBigEndian,
        ] {
            out.push((f, to_bytes_with(m.positions(), m.triangles(), f, enc)));
        }
    }
    // a seamed, skinned, two-primitive glTF asset, both containers
    for (f, container) in [
        (Format::Glb, Container::Glb),
        (Format::Gltf, Container::Json),
    ] {
        let o = TubeOptions {
            around: 4,
            rings: 3,
            skinned: true,
            container,
        };
        out.push((f, sample::tube(o).unwrap()));
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        for f in Format::ALL {
            let _ = parse_bytes(&bytes, f);
        }
        let _ = parse_sel(&bytes);
        let _ = parse_def(&bytes);
    }

    #[test]
    fn mutated_valid_files_never_panic(
        which in 0usize..20,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let (f, mut bytes) = seeds().swap_remove(which);
        for (at, byte, op) in edits {
            let i = at.index(bytes.len());
            match op {
                0 => bytes[i] = byte,
                1 => bytes.insert(i, byte),
                _ => { bytes.remove(i); }
            }
        }
        let _ = parse_bytes(&bytes, f);
        // the asset reader (layout, weld, normals, export) neither
        if let Ok(a) = Asset::read_bytes(&bytes, f, Sidecars::Refuse) {
            let _ = a.export(a.mesh().positions(), f);
        }
        let n = cut.index(bytes.len() + 1);
        if let Ok(raw) = parse_bytes(&bytes[..n], f) {
            // whatever parses either validates or is rejected, without panicking
            let _ = raw.into_mesh();
        }
    }

    #[test]
    fn text_headers_with_any_counts_never_panic(nv in any::<u64>(), nf in any::<u64>(), body in "[0-9 .\\n-]{0,200}") {
        let off = format!("OFF\n{nv} {nf} 0\n{body}");
        let _ = parse_bytes(off.as_bytes(), Format::Off);
        let ply = format!("ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\nelement face {nf}\nproperty list uint int vertex_indices\nend_header\n{body}");
        let _ = parse_bytes(ply.as_bytes(), Format::Ply);
        let plyb = ply.replace("ascii", "binary_little_endian");
        let _ = parse_bytes(plyb.as_bytes(), Format::Ply);
    }
}
