//! Round trips through every reader/writer and encoding.

use dend::mesh::gen::{generate, Shape, ShapeSpec};
use dend::mesh::io::{parse_bytes, parse_json, read_bytes, to_bytes_with, Encoding, Format};
use dend::mesh::{Mesh, Point};
use proptest::prelude::*;

const ENCODINGS: [Encoding; 3] = [
    Encoding::Ascii,
    Encoding::BinaryLittleEndian,
    Encoding::BinaryBigEndian,
];

/// Triangles as corner-position triples, rotated so the smallest comes first, sorted:
/// compares meshes up to vertex renumbering (STL welding reorders vertices).
fn soup(p: &[Point], t: &[[u32; 3]]) -> Vec<[[u64; 3]; 3]> {
    let mut s: Vec<[[u64; 3]; 3]> = t
        .iter()
        .map(|f| {
            let c = f.map(|i| p[i as usize].map(f64::to_bits));
            let k = (0..3).min_by_key(|&k| c[k]).unwrap();
            [c[k], c[(k + 1) % 3], c[(k + 2) % 3]]
        })
        .collect();
    s.sort();
    s
}

/// Writes `m` in every format/encoding and checks it reads back identically
/// (exactly for indexed formats; up to welding/renumbering for STL, whose
/// binary form is `f32`).
fn round_trip(m: &Mesh) {
    for f in Format::ALL {
        for enc in ENCODINGS {
            if f == Format::Stl && enc == Encoding::BinaryBigEndian {
                continue;
            }
            let bytes = to_bytes_with(m.positions(), m.triangles(), f, enc);
            let back = read_bytes(&bytes, f).unwrap_or_else(|e| panic!("{f} {enc:?}: {e}"));
            if f == Format::Stl {
                let p32: Vec<Point> = m
                    .positions()
                    .iter()
                    .map(|p| {
                        if enc == Encoding::Ascii {
                            *p
                        } else {
                            p.map(|c| c as f32 as f64)
                        }
                    })
                    .collect();
                assert_eq!(
                    soup(back.positions(), back.triangles()),
                    soup(&p32, m.triangles()),
                    "{f} {enc:?}"
                );
            } else if matches!(f, Format::Gltf | Format::Glb) {
                // glTF stores f32 positions; the numbering is kept
                let p32: Vec<Point> = m
                    .positions()
                    .iter()
                    .map(|p| p.map(|c| c as f32 as f64))
                    .collect();
                assert_eq!(back.positions(), &p32[..], "{f}");
                assert_eq!(back.triangles(), m.triangles(), "{f}");
            } else {
                assert_eq!(back.positions(), m.positions(), "{f} {enc:?}");
                assert_eq!(back.triangles(), m.triangles(), "{f} {enc:?}");
            }
        }
    }
}

#[test]
fn generated_shapes_round_trip_in_every_format() {
    for s in [
        Shape::Bar,
        Shape::Cylinder,
        Shape::Flag,
        Shape::BumpyPlane,
        Shape::Torus,
    ] {
        round_trip(&generate(&ShapeSpec::default_for(s)).unwrap());
    }
}

#[test]
fn stl_welds_back_to_the_same_vertex_count() {
    let m = generate(&ShapeSpec::default_for(Shape::Torus)).unwrap();
    for enc in [Encoding::Ascii, Encoding::BinaryLittleEndian] {
        let back = read_bytes(
            &to_bytes_with(m.positions(), m.triangles(), Format::Stl, enc),
            Format::Stl,
        )
        .unwrap();
        assert_eq!(back.num_vertices(), 576);
        assert_eq!(back.genus(), 1);
    }
}

#[test]
fn json_form_parses_and_reports_positions() {
    let raw =
        parse_json(br#"{"positions": [[0,0,0],[1,0,0],[0,1,0]], "triangles": [[0,1,2]]}"#).unwrap();
    assert_eq!(raw.triangles, vec![[0, 1, 2]]);
    let e = parse_json(b"{\"positions\": [[0,0,0]],\n \"triangles\": [[0,1]]}").unwrap_err();
    assert!(e.to_string().contains("line 2"), "{e}");
}

#[test]
fn writers_accept_a_deformed_pose() {
    let m = generate(&ShapeSpec::default_for(Shape::Flag)).unwrap();
    let pose: Vec<Point> = m
        .positions()
        .iter()
        .map(|p| [p[0], p[1], p[0] * p[0]])
        .collect();
    let raw = parse_bytes(
        &to_bytes_with(&pose, m.triangles(), Format::Off, Encoding::Ascii),
        Format::Off,
    )
    .unwrap();
    assert_eq!(raw.positions, pose);
}

/// A random height-field grid with random extra (unreferenced) vertices.
fn random_mesh() -> impl Strategy<Value = Mesh> {
    (2usize..7, 2usize..7, 0usize..3)
        .prop_flat_map(|(nx, ny, extra)| {
            (
                Just((nx, ny)),
                prop::collection::vec(-1e6f64..1e6, nx * ny),
                prop::collection::vec(prop::array::uniform3(-1e3f64..1e3), extra),
            )
        })
        .prop_map(|((nx, ny), h, extra)| {
            let mut p: Vec<Point> = (0..nx * ny)
                .map(|k| [(k % nx) as f64 * 1.5, (k / nx) as f64 * 0.75, h[k]])
                .collect();
            p.extend(extra);
            let mut t = Vec::new();
            for j in 0..ny - 1 {
                for i in 0..nx - 1 {
                    let v = (j * nx + i) as u32;
                    let n = nx as u32;
                    t.push([v, v + 1, v + 1 + n]);
                    t.push([v, v + 1 + n, v + n]);
                }
            }
            Mesh::new(p, t).unwrap()
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn random_meshes_round_trip_exactly(m in random_mesh()) {
        for f in [Format::Obj, Format::Off, Format::Ply] {
            for enc in ENCODINGS {
                let back = parse_bytes(&to_bytes_with(m.positions(), m.triangles(), f, enc), f).unwrap();
                prop_assert_eq!(&back.positions[..], m.positions());
                prop_assert_eq!(&back.triangles[..], m.triangles());
            }
        }
        let back = parse_bytes(&to_bytes_with(m.positions(), m.triangles(), Format::Stl, Encoding::Ascii), Format::Stl).unwrap();
        prop_assert_eq!(soup(&back.positions, &back.triangles), soup(m.positions(), m.triangles()));
    }
}
