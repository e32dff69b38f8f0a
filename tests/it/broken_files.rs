//! The corpus in `tests/data/broken/` (listed with the expected error kind in
//! `EXPECTED`): every file is rejected with that kind, never a panic.

use std::path::PathBuf;

use dend::mesh::io::{read_path, IoError, Position};
use dend::mesh::MeshError;

fn kind(e: &IoError) -> &'static str {
    match e {
        IoError::Parse { .. } => "parse",
        IoError::Mesh(m) => match m {
            MeshError::Empty { .. } => "empty",
            MeshError::TooLarge { .. } => "too_large",
            MeshError::NonFinite { .. } => "non_finite",
            MeshError::IndexOutOfRange { .. } => "index_out_of_range",
            MeshError::RepeatedIndex { .. } => "repeated_index",
            MeshError::ZeroArea { .. } => "zero_area",
            MeshError::NonManifoldEdge { .. } => "non_manifold_edge",
            MeshError::InconsistentOrientation { .. } => "inconsistent_orientation",
            MeshError::NonManifoldVertex { .. } => "non_manifold_vertex",
            MeshError::VertexCountMismatch { .. } => "vertex_count_mismatch",
        },
        IoError::Io { .. } => "io",
        IoError::UnknownFormat { .. } => "unknown_format",
        IoError::Json { .. } => "json",
    }
}

#[test]
fn every_broken_file_gives_its_expected_error() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/broken");
    let list = std::fs::read_to_string(dir.join("EXPECTED")).unwrap();
    let mut n = 0;
    for line in list
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
    {
        let (file, expected) = line.split_once(' ').unwrap();
        let err = match read_path(&dir.join(file)) {
            Ok(m) => panic!("{file}: accepted ({} vertices)", m.num_vertices()),
            Err(e) => e,
        };
        assert_eq!(kind(&err), expected, "{file}: {err}");
        if let IoError::Parse {
            position: Position::Line(l),
            ..
        } = &err
        {
            // text inputs name a 1-based line
            assert!(*l >= 1, "{file}: {err}");
        }
        n += 1;
    }
    assert!(n >= 40, "only {n} corpus entries");
    // every file in the folder is listed
    let files = std::fs::read_dir(&dir).unwrap().count() - 1;
    assert_eq!(files, n, "unlisted files in tests/data/broken");
}

#[test]
fn positions_point_at_the_problem() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/broken");
    let pos = |f: &str| match read_path(&dir.join(f)) {
        Err(IoError::Parse { position, .. }) => position,
        other => panic!("{f}: {other:?}"),
    };
    assert_eq!(pos("truncated.obj"), Position::Line(4));
    assert_eq!(pos("truncated_face.off"), Position::Line(6));
    assert_eq!(pos("negative_index.off"), Position::Line(6));
    assert!(matches!(pos("truncated_binary.ply"), Position::Byte(_)));
    assert!(matches!(pos("huge_counts.stl"), Position::Byte(134)));
    assert!(matches!(pos("truncated_binary.stl"), Position::Byte(134)));
}
